"""A user's own mesh end to end from the command line (docs/export.md "Your own mesh"):
`caustics-jax export --scene PATH` exports that scene alone, named after the file, placed
as `compare --scene PATH` places it, with the scene options (`--light`, `--floor-depth`,
`--eta`, `--scene-file`), and `caustics-jax conformance DIR` runs it."""

import argparse
import json

import numpy as np
import pytest
import trimesh

from caustics_jax.app import cli
from caustics_jax.app.compare import CompareConfig, load_scene
from caustics_jax.app.scene_file import read_scene_file, scene_options
from caustics_jax.testing.jittered_wave import jittered_heightfield


@pytest.fixture(scope="module")
def obj(tmp_path_factory):
    """A jittered heightfield nobody registered, as an OBJ (2048 triangles: the exported
    scenes' size class, so the export's programs are shared with tests/test_export.py)."""
    mesh = jittered_heightfield(32, seed=4, half=1.5)
    path = tmp_path_factory.mktemp("own") / "my pool.obj"
    trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False).export(path)
    return path


def test_export_scene_path_exports_that_scene_alone_and_conformance_runs_it(obj, tmp_path, capsys):
    out = tmp_path / "data"
    argv = ["export", "--out", str(out), "--scene", str(obj), "--lanes", "64", "--light", "0.2", "-0.1", "2.5",
            "--floor-depth", "0.7", "--eta", "1.5"]
    assert cli.main(argv) == 0
    assert "scenes: my_pool" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["caustics_scene.h", "my_pool.bin", "my_pool.json",
                                                     "my_pool.newton.bin", "my_pool.newton.json"]
    m = json.loads((out / "my_pool.json").read_text())
    assert m["scene"] == "my_pool" and abs(m["eta"] - 1.5) < 1e-6 and "my pool.obj" in m["source"]
    assert "point light at [0.2, -0.1, 2.5]" in m["source"] and str(obj.parent) not in json.dumps(m)
    code = cli.main(["conformance", str(out)])
    captured = capsys.readouterr()
    if code == 3:
        pytest.skip(f"no Vulkan toolchain or device: {captured.err.strip()}")
    assert code == 0, captured.err
    assert "| my_pool | walk | 64 (" in captured.out and "| my_pool | newton | 64 (" in captured.out


def test_a_scene_file_gives_the_options_and_flags_win_over_it(obj, tmp_path):
    toml = tmp_path / "scene.toml"
    toml.write_text(f'scene = "{obj.name}"\nlight = [0.2, -0.1, 2.5]\nfloor_depth = 0.7\neta = 1.4\nlanes = 32\n')
    (tmp_path / obj.name).write_bytes(obj.read_bytes())  # the scene path is relative to the file
    opts = read_scene_file(toml)
    assert opts == {"scene": str(tmp_path / obj.name), "light": (0.2, -0.1, 2.5), "floor_depth": 0.7,
                    "eta": 1.4, "lanes": 32}
    args = argparse.Namespace(scene_file=str(toml), scene=None, light=None, floor_depth=None, eta=1.2, lanes=None)
    got = scene_options(args, {"scene": None, "light": None, "floor_depth": None, "eta": 1.333, "lanes": 256})
    assert got["eta"] == 1.2 and got["light"] == (0.2, -0.1, 2.5) and got["lanes"] == 32


@pytest.mark.parametrize("text, match", [
    ('scene = "a.obj"\nlihgt = [0, 0, 1]\n', r"unknown key\(s\) \['lihgt'\]"),
    ('light = [0, 0]\n', "light must be one finite point"),
    ('floor_depth = -1\n', "floor_depth must be a finite real number in \\(0"),
    ('eta = "water"\n', "eta must be one finite positive real number"),
    ('scene = \n', "is not a TOML scene description"),
])
def test_a_bad_scene_file_is_one_line_naming_the_file_and_key(tmp_path, capsys, text, match):
    toml = tmp_path / "bad.toml"
    toml.write_text(text)
    with pytest.raises(ValueError, match=match):
        read_scene_file(toml)
    assert cli.main(["export", "--out", str(tmp_path / "o"), "--scene-file", str(toml)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.toml" in err


def test_scene_options_without_a_mesh_of_ones_own_are_refused(tmp_path, capsys):
    assert cli.main(["export", "--out", str(tmp_path / "o"), "--light", "0", "0", "3"]) == 2
    assert "give it with --scene PATH" in capsys.readouterr().err
    assert cli.main(["export", "--out", str(tmp_path / "o"), "--scene", str(tmp_path / "missing.obj")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_compare_scene_options_move_the_light_and_the_floor_of_named_scenes_and_mesh_files(obj):
    sc = load_scene("wavy", 512, light=(1.0, 2.0, 3.0), floor_depth=2.0)
    assert np.allclose(np.asarray(sc.lights.position)[0], [1, 2, 3]) and np.allclose(np.asarray(sc.receivers)[:, 2], -2)
    sc = load_scene(str(obj), light=(0.2, -0.1, 2.5), floor_depth=0.7)
    z_min = float(np.asarray(sc.surface.vertices)[:, 2].min())
    assert np.allclose(np.asarray(sc.receivers)[:, 2], z_min - 0.7)
    assert np.allclose(np.asarray(sc.lights.position)[0], [0.2, -0.1, 2.5])
    for bad, match in (({"light": (0.0, 0.0)}, "light must be one finite point"),
                       ({"floor_depth": 0.0}, "floor_depth must be")):
        with pytest.raises(ValueError, match=match):
            CompareConfig(**bad).validate()


def test_a_sun_scene_exports_and_passes_conformance(obj, tmp_path, capsys):
    """`--sun`: the lanes carry the directional light's points at float32's limit distance
    (math.md §9) and the radiant intensity that gives their `E_perp`; every lane stays
    conditioned (the crossing tolerance's `|s| |d|`: with `|d|` alone every lane had been
    set apart as a tie) and the GLSL port agrees with the testbed."""
    out = tmp_path / "sun"
    assert cli.main(["export", "--out", str(out), "--scene", str(obj), "--lanes", "64",
                     "--sun", "0.3", "0.05", "-1"]) == 0
    m = json.loads((out / "my_pool.json").read_text())
    assert "directional light travelling along" in m["source"]
    assert m["summary"]["conditioned"] == 64
    code = cli.main(["conformance", str(out)])
    captured = capsys.readouterr()
    if code == 3:
        pytest.skip(f"no Vulkan toolchain or device: {captured.err.strip()}")
    assert code == 0, captured.err
    assert "| my_pool | walk | 64 (64) |" in captured.out and "| my_pool | newton | 64 (64) |" in captured.out
