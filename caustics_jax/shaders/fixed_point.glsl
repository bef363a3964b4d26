// 4.28 fixed-point accumulation with wrapping 32-bit integer adds (seed 000 §3.2;
// kernels.fixed_point). Encode: round half to even of x 2^28, saturated at 2^32 - 1 for
// x >= 16 (MAX_VALUE); a sequential wrapping add gives the word InterlockedAdd/atomicAdd
// leaves, whatever the order; uaddCarry reports the overflow the hardware cannot.
uint cj_fixed_point_encode(float x) {
    if (x >= 16.0) return 0xFFFFFFFFu;  // below 16, x 2^28 <= 2^32 - 256 is exact in float32
    return uint(roundEven(max(x, 0.0) * 268435456.0));
}

void cj_run(inout Record r) {
    uint code = 0u;
    uint overflow = 0u;
    for (int i = 0; i < r.x.length(); ++i) {
        uint carry;
        code = uaddCarry(code, cj_fixed_point_encode(r.x[i]), carry);
        overflow |= carry;
    }
    r.code = code;
    r.overflow = overflow;
    r.value = float(code) * (1.0 / 268435456.0);
}
