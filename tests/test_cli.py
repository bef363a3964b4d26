"""`caustics-jax compare`: one small end-to-end run (table, JSON, figure) and its errors."""

import json

import numpy as np
import pytest

from caustics_jax import cli
from caustics_jax.compare import CompareConfig, ratios


def test_compare_writes_a_table_json_and_figure_consistent_with_the_reference(tmp_path, capsys):
    out_json, out_png = tmp_path / "cmp.json", tmp_path / "cmp.png"
    # sweep_n == n: the sweep reuses the main call's compiled shape
    rc = cli.main(["compare", "--n", "64", "--dtype", "float64", "--configs", "walk", "newton-hv",
                   "--ref-n", "24", "--sweep-n", "64", "--repeats", "1", "--triangles", "512",
                   "--json", str(out_json), "--figure", str(out_png)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "walk / best Newton (newton-hv) throughput ratio" in text
    report = json.loads(out_json.read_text())
    assert {r["config"] for r in report["rows"]} == {"walk", "newton-hv"}
    assert report["reference"]["lanes"] == 24
    for r in report["rows"]:
        # every lane of this gentle pool has exactly one solution (the reference says so) and
        # both solvers find it: success is counted against the reference, not self-reported
        assert report["reference"]["solutions_per_lane"] == [0, 24]
        assert r["success"] == 1.0 and r["nearest_M0"] == 1.0 and r["spurious"] == 0
        assert r["position_error_m"]["max"] < 1e-9  # float64, tol 1e-10 on the sine
        assert r["angle_error_rad"]["max"] < 1e-9
        assert r["solves_per_s"] > 0 and np.isfinite(r["compile_s"])
        assert r["config"] in text
    sweep_tols = sorted({s["tol"] for s in report["sweep"] if s["config"] == "walk"})
    assert len(sweep_tols) >= 4
    # a looser acceptance tolerance can only give larger worst-case errors
    walk = sorted((s for s in report["sweep"] if s["config"] == "walk"), key=lambda s: s["tol"])
    assert walk[0]["angle_error_rad"]["max"] <= walk[-1]["angle_error_rad"]["max"]
    assert out_png.stat().st_size > 10_000
    assert ratios(report)[0]["speed_ratio"] > 0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(scene="ocean"), "scene"),
        (dict(configs=("walk", "newton-magic")), "unknown solver configs"),
        (dict(dtypes=("float16",)), "dtypes"),
        (dict(n=0), "n, sweep_n"),
    ],
)
def test_bad_compare_configuration_raises_value_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CompareConfig(**kwargs).validate()


def test_cli_reports_bad_configuration_with_exit_code_2(capsys):
    assert cli.main(["compare", "--configs", "walk", "nonsense", "--n", "8"]) == 2
    assert "unknown solver configs" in capsys.readouterr().err
