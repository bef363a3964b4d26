"""`caustics-jax compare`: one small end-to-end run (table, JSON, figure) and its errors."""

import json

import numpy as np
import pytest

from caustics_jax.app import cli
from caustics_jax.app.compare import CompareConfig, ratios


def test_compare_writes_a_table_json_and_figure_consistent_with_the_reference(tmp_path, capsys):
    out_json, out_png = tmp_path / "cmp.json", tmp_path / "cmp.png"
    # sweep_n == n: the sweep reuses the main call's compiled shape
    rc = cli.main(["compare", "--n", "64", "--dtype", "float64", "--configs", "walk", "newton-hv",
                   "--ref-n", "24", "--sweep-n", "64", "--repeats", "1", "--triangles", "512",
                   "--json", str(out_json), "--figure", str(out_png), "--frame", "8x8"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "walk / best Newton (newton-hv) throughput ratio" in text
    report = json.loads(out_json.read_text())
    # the frame (64 receivers: the table's block shape, nothing compiled again): the walk
    # (the one-step Newton is not in this table)
    assert [(f["config"], f["width"] * f["height"]) for f in report["frames"]] == [("walk", 64)]
    assert all(f["seconds"] > 0 for f in report["frames"]) and "[float64] walk: a 8x8 frame (64 receivers)" in text
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
        (dict(n=0), r"n must be an integer in \[1, "),
        (dict(frame=(960,)), "frame must be"),
        (dict(frame=(960, 0)), "frame height"),
    ],
)
def test_bad_compare_configuration_raises_value_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CompareConfig(**kwargs).validate()


def test_cli_reports_bad_configuration_with_exit_code_2(capsys):
    assert cli.main(["compare", "--configs", "walk", "nonsense", "--n", "8"]) == 2
    assert "unknown solver configs" in capsys.readouterr().err


# --------------------------------------------------------------------------- user errors
# (docs/input_contract.md "Command line"): one line on stderr, exit status 2, before any work.


@pytest.fixture
def no_run(monkeypatch):
    """The comparison must not start: every user error is caught before `compare.run`."""
    def boom(cfg):
        raise AssertionError("the run started before the error was reported")

    monkeypatch.setattr(cli.cmp, "run", boom)


def _one_line_error(capsys, *needles):
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err
    return err


@pytest.mark.parametrize("argv, needle", [
    (["--eta", "-1"], "eta must be one finite positive"), (["--eta", "nan"], "eta must be one finite positive"),
    (["--eta", "inf"], "eta"), (["--eta", "1e39"], "eta overflows float32"),
    (["--eta", "1e-40"], "eta must be at least"),
    (["--n", "0"], "n must be an integer"), (["--n", str(2**40)], "n must be an integer"),
    (["--triangles", "-5"], "n_triangles"), (["--repeats", "0"], "repeats"), (["--seed", "-1"], "seed"),
    (["--ref-n", "-1"], "ref_n"), (["--sweep-n", "0"], "sweep_n"), (["--scene", "missing.obj"], "does not exist"),
    (["--scene", "ocean"], "scene must be one of"), (["--configs", "walk", "nonsense"], "unknown solver configs"),
    (["--figure", "out.nothing"], "file type is set by the suffix"),
    (["--n", "abc"], "invalid int value"), (["--dtype", "float16"], "invalid choice"),
    (["--cpu-devices", "0"], "positive integer or 'all'"), (["--cpu-devices", "two"], "positive integer or 'all'"),
    (["--cpu-devices", "100000"], "at most"),
])
@pytest.mark.parametrize("command", ["compare", "demo"])
def test_compare_user_errors_exit_2_with_one_line_before_the_run(no_run, capsys, command, argv, needle):
    assert cli.main([command, *argv]) == 2
    _one_line_error(capsys, f"caustics-jax {command}: ", needle)


def test_compare_output_paths_are_checked_before_the_run(no_run, capsys, tmp_path):
    a_file = tmp_path / "file.txt"
    a_file.write_text("x")
    for flag, path, needle in [("--json", tmp_path, "is a directory"), ("--figure", tmp_path, "is a directory"),
                               ("--json", a_file / "sub.json", "is a file, not a directory"),
                               ("--figure", a_file / "sub" / "f.png", "is a file, not a directory")]:
        assert cli.main(["compare", "--n", "8", flag, str(path)]) == 2
        _one_line_error(capsys, flag, needle)
    assert not (tmp_path / "out").exists()  # nothing created by the checks


def test_an_unwritable_output_directory_is_refused(no_run, capsys, tmp_path, monkeypatch):
    # (root may write anywhere: the permission test asks os.access, so ask it to say no)
    monkeypatch.setattr(cli.os, "access", lambda path, mode: False)
    assert cli.main(["compare", "--json", str(tmp_path / "r.json")]) == 2
    _one_line_error(capsys, "--json", "is not writable")


def test_errors_raised_during_the_run_are_one_line_too(monkeypatch, capsys):
    def fail(cfg):
        raise ValueError("a solver is unavailable in this dtype")

    monkeypatch.setattr(cli.cmp, "run", fail)
    assert cli.main(["compare", "--n", "8"]) == 2
    _one_line_error(capsys, "caustics-jax compare: a solver is unavailable")

    def denied(cfg):
        raise PermissionError(13, "Permission denied", "/root/x.json")

    monkeypatch.setattr(cli.cmp, "run", denied)
    assert cli.main(["compare", "--n", "8"]) == 1
    _one_line_error(capsys, "caustics-jax compare: Permission denied", "/root/x.json")


def test_a_long_comparison_warns_with_its_size_and_time(no_run, capsys):
    assert cli.warn_if_long_compare(CompareConfig()) is None  # the default demo: no warning
    big = CompareConfig(n=10**7)
    msg = cli.warn_if_long_compare(big)
    # 10^7 lanes x 5 configurations x 2 dtypes x 3 timed calls plus the sweep, at 40k solves/s
    assert f"about {big.expected_solves():.3g} solver lanes" in msg
    assert big.expected_solves() >= 10**7 * 5 * 2 * 3
    assert f"about {big.expected_solves() / cli.SOLVES_PER_S / 60:.0f} min" in msg
    with pytest.raises(AssertionError, match="run started"):  # warned on stderr, then the run starts
        cli.main(["compare", "--n", str(10**7)])
    err = capsys.readouterr().err
    assert "warning: --n 10000000" in err and "min of solver time" in err


def test_export_count_beyond_a_storage_buffer_is_refused_and_a_large_one_warns(capsys, tmp_path, monkeypatch):
    from caustics_jax import export

    assert cli.main(["export", "--out", str(tmp_path / "d"), "--count", str(2**40)]) == 2
    _one_line_error(capsys, "caustics-jax export: --count", "4 GiB")
    assert not (tmp_path / "d").exists()  # refused before anything was written
    assert cli.export_size_warning(list(export.KERNELS), 256, 256, 0) is None
    msg = cli.export_size_warning(list(export.KERNELS), 10**6, 256, 0)
    assert "MiB of binaries" in msg and "min" in msg

    def no_export(*a, **k):
        raise AssertionError("exported")

    monkeypatch.setattr(export, "export", no_export)
    with pytest.raises(AssertionError, match="exported"):
        cli.main(["export", "--out", str(tmp_path / "e"), "--count", str(10**6)])
    assert "warning: --count 1000000" in capsys.readouterr().err


def test_conformance_errors_carry_the_command_prefix(capsys, tmp_path):
    """`caustics-jax conformance` prefixes its one-line errors like the other commands
    (it printed `conformance: ...`)."""
    assert cli.main(["conformance", str(tmp_path / "missing")]) == 2
    _one_line_error(capsys, "caustics-jax conformance: ", "no exported kernels or scenes")


@pytest.mark.parametrize("argv, flag", [
    (["export", "--out", "", "--kernels", "fresnel", "--count", "8"], "--out"),
    (["compare", "--n", "8", "--json", ""], "--json"), (["demo", "--figure", ""], "--figure"),
    (["conformance", ""], "data"), (["conformance", "refdata", "--json", ""], "--json"),
])
def test_an_empty_path_is_refused_in_one_line(no_run, capsys, tmp_path, monkeypatch, argv, flag):
    """`export --out ""` had written into the current directory (`Path("")` is `.`); an empty
    `--json` or `--figure` had read "is a directory", an empty conformance `data` had read `.`."""
    from caustics_jax import export

    def no_work(*args, **kwargs):
        raise AssertionError("export started working on an empty --out")

    monkeypatch.setattr(export.writer, "export_kernel", no_work)
    monkeypatch.chdir(tmp_path)
    assert cli.main(argv) == 2
    _one_line_error(capsys, f"caustics-jax {argv[0]}: {flag}", "empty path")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("argv", [["--scenes", "none"], ["--kernels", "none"],
                                  ["--kernels", "none", "--scenes", "none"]])
def test_an_export_that_selects_nothing_is_an_error(capsys, tmp_path, argv):
    """`--scenes none` alone selects no kernel either (as the help says); it had written 0
    files and exited 0."""
    assert cli.main(["export", "--out", str(tmp_path / "d"), *argv]) == 2
    _one_line_error(capsys, "caustics-jax export: nothing to export", "no kernel and no scene")
    assert not (tmp_path / "d").exists()


def test_warnings_from_the_command_line_are_one_line_with_the_command_not_the_entry_point(capsys):
    """A warning raised during a command stays a warning (filters apply) but reads
    `caustics-jax CMD: warning: ...`, not the entry-point script's path and line."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("always")
        with cli._warnings_as_lines("caustics-jax compare"):  # noqa: SLF001
            warnings.warn("the light is below the surface", UserWarning, stacklevel=1)
            warnings.warn("old option", DeprecationWarning, stacklevel=1)
        err = capsys.readouterr().err
        assert err == ("caustics-jax compare: warning: the light is below the surface\n"
                       "caustics-jax compare: DeprecationWarning: old option\n")
        warnings.simplefilter("ignore")
        with cli._warnings_as_lines("caustics-jax compare"):  # noqa: SLF001
            warnings.warn("ignored", UserWarning, stacklevel=1)
        assert capsys.readouterr().err == ""
