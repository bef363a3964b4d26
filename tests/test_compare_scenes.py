"""`caustics-jax compare --scene PATH`: a mesh file read through trimesh, its floor and light;
`--version`; the CLI writes no file it was not asked for."""

import numpy as np
import pytest
import trimesh

from caustics_jax import __version__
from caustics_jax.app import cli, compare


def _ripple_obj(path, n=16, size=4.0):
    """A rippled n x n grid rotated by 30 degrees (off any axis-aligned grid), +z normals."""
    u = np.linspace(-size / 2, size / 2, n + 1)
    X, Y = np.meshgrid(u, u, indexing="xy")
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    x, y = c * X - s * Y, s * X + c * Y
    z = 0.03 * np.cos(2 * np.pi * np.hypot(x, y) / 1.3)
    V = np.stack([x.ravel(), y.ravel(), z.ravel()], -1)
    i = np.arange(n)[None, :] + (n + 1) * np.arange(n)[:, None]
    a, b, d, e = i, i + 1, i + n + 1, i + n + 2
    F = np.concatenate([np.stack([a, b, e], -1).reshape(-1, 3), np.stack([a, e, d], -1).reshape(-1, 3)])
    trimesh.Trimesh(V, F, process=False).export(path)
    return V


def test_scene_from_a_mesh_file_has_its_floor_under_the_mesh_and_the_light_above(tmp_path):
    V = _ripple_obj(tmp_path / "ripple.obj")
    sc = compare.load_scene(str(tmp_path / "ripple.obj"))
    assert sc.surface.faces.shape[0] == 2 * 16 * 16
    lo, hi = V.min(0), V.max(0)
    W = max(hi[0] - lo[0], hi[1] - lo[1])
    R = np.asarray(sc.receivers)
    np.testing.assert_allclose(R[:, 2], lo[2] - W / 4)
    assert np.all(R[:, :2] >= lo[:2]) and np.all(R[:, :2] <= hi[:2])
    light = np.asarray(sc.lights.position)[0]
    np.testing.assert_allclose(light[2], hi[2] + 0.75 * W)
    # the surface's normals face the light (+z), as in every built-in scene
    assert np.all(np.asarray(sc.surface.normals)[:, 2] > 0)


def test_compare_runs_on_a_mesh_file_and_writes_nothing_unasked(tmp_path, monkeypatch, capsys):
    _ripple_obj(tmp_path / "ripple.obj")
    work = tmp_path / "cwd"
    work.mkdir()
    monkeypatch.chdir(work)
    # the sizes of tests/test_cli.py (64 lanes, 512 faces, float64): the same compiled walk
    rc = cli.main(["compare", "--scene", str(tmp_path / "ripple.obj"), "--n", "64", "--dtype", "float64",
                   "--configs", "walk", "--ref-n", "16", "--no-sweep", "--repeats", "1"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "ripple.obj (512 triangles)" in out and "no files written" in out
    assert list(work.iterdir()) == []  # no figures/ or JSON dropped into the current directory
    row = next(line for line in out.splitlines() if line.startswith("walk"))
    success = float(row.split()[2])
    assert success == 1.0  # every reference lane with a path is found on this gentle ripple


@pytest.mark.parametrize("content, match", [(None, "does not exist"),
                                            (b"not a mesh \x00\x01", "holds no usable triangle mesh")])
def test_bad_scene_file_is_a_value_error(tmp_path, content, match):
    path = tmp_path / "surface.obj"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(ValueError, match=match):
        compare.load_scene(str(path))


def test_cli_reports_a_missing_scene_file_with_exit_code_2(tmp_path, capsys):
    assert cli.main(["compare", "--scene", str(tmp_path / "missing.ply"), "--n", "8"]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_version_flag_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"caustics-jax {__version__}"


@pytest.mark.parametrize("events, cached", [((), False), (("cache_hits",), True),
                                            (("cache_hits", "cache_misses"), False), (("cache_misses",), False)])
def test_compile_time_is_marked_cached_only_when_nothing_was_compiled(events, cached):
    """`compare._timed` marks a first call "c" (a load time) only when it loaded programs
    from the persistent cache and wrote none: a solver recompiled after a code change,
    next to small programs loaded from the cache, keeps its real compile time."""
    import jax

    calls = []

    def fn():
        if not calls:  # the first call: JAX's events for its programs
            for e in events:
                jax.monitoring.record_event(f"/jax/compilation_cache/{e}")
        calls.append(1)
        return np.zeros(1)

    _, compile_s, steady, got = compare._timed(fn, repeats=2)
    assert got is cached and len(calls) == 3 and compile_s >= 0 and steady >= 0


def test_a_mesh_file_outside_the_scale_band_is_a_user_error_before_the_run(tmp_path, capsys):
    """A pool 4e10 m wide in float32 (beyond `arguments.scale_range`): compare had logged
    "skipped" per config and printed an empty table with exit status 0."""
    _ripple_obj(tmp_path / "huge.obj", size=4e10)
    rc = cli.main(["compare", "--scene", str(tmp_path / "huge.obj"), "--n", "4", "--dtype", "float32",
                   "--configs", "walk", "--ref-n", "0", "--no-sweep", "--repeats", "1"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "beyond what float32 resolves" in err[0], err
