"""The Python module against the command line (run by ctest as Python.pytest, with
PYTHONPATH at the build tree's python/ and TUILE_BINARY the tuile binary)."""
import csv
import os
import subprocess
import sys

import numpy as np
import pytest

import tuile

TUILE = os.environ.get("TUILE_BINARY", "tuile")
SOURCE = os.environ.get("TUILE_SOURCE_DIR", os.path.join(os.path.dirname(__file__), "..", ".."))


def cli(*args):
    r = subprocess.run([TUILE, *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r


@pytest.fixture(scope="module")
def cornell():
    return tuile.load("built-in:cornell")


# The same flags give the same bits as `tuile render` (the EXR holds float32 RGB): direct
# lighting, paths, every picker and heuristic kind, a sampler and a filter given.
CASES = [
    dict(spp=8, res="48x36", strategy="mis", seed=3),
    dict(spp=4, res=(40, 30), strategy="mis", light_pick="bvh", heuristic="balance", max_depth=5, sampler="independent"),
    dict(spp=4, res="40x30", strategy="light", light_pick="uniform", light_point="area", filter="gaussian", tile=8),
    dict(spp=4, res="40x30", strategy="ris", ris_light=4, max_depth=3, beta=1.5),
    dict(spp=4, res="40x30", strategy="mis", max_depth=4, regularize="on"),
    dict(spp=6, res="40x30", strategy="mis", max_depth=4, guide=True, guide_learn=2, guide_alpha=0.25),
    dict(spp=4, res="40x30", strategy="mis", max_depth=4, light_paths=True),
    dict(spp=4, res="40x30", strategy="light", max_depth=3, light_paths="off"),
]


def cli_args(flags):
    args = []
    for k, v in flags.items():
        if v is True:  # a flag without a value
            args.append("--" + k.replace("_", "-"))
            continue
        if k == "res" and isinstance(v, tuple):
            v = "%dx%d" % v
        args.append("--%s=%s" % (k.replace("_", "-"), v))  # (one token, as a flag's value must be)
    return args


@pytest.mark.parametrize("flags", CASES, ids=lambda f: f["strategy"] + "-" + str(f.get("max_depth", 1)))
def test_render_equals_the_command_line_bit_for_bit(cornell, tmp_path, flags):
    out = tmp_path / "cli.exr"
    cli("render", "built-in:cornell", *cli_args(flags), "-o", out, "--quiet")
    want = tuile.read_exr(str(out))
    got = cornell.render(**flags)
    assert got.dtype == np.float32 and got.shape == want.shape
    assert np.array_equal(got, want), "largest difference %g" % np.abs(got - want).max()


def test_render_writes_the_same_exr_when_asked(cornell, tmp_path):
    img = cornell.render(spp=2, res="32x24", output=str(tmp_path / "py.exr"))
    assert np.array_equal(tuile.read_exr(str(tmp_path / "py.exr")), img)
    assert (tmp_path / "py.png").exists()


def test_arrays_share_memory_with_the_film(cornell):
    img, aovs = cornell.render(spp=4, res="32x24", aovs=["variance", "mis_weight"])
    film = img.base
    assert isinstance(film, tuile.Film)
    assert not img.flags.owndata
    assert img.ctypes.data == film.image_address  # the film's own buffer, not a copy
    assert np.shares_memory(img, film.image)
    assert img.shape == (24, 32, 3) and film.spp == 4 and film.stopped_by == "complete"
    assert aovs["variance"].shape == (24, 32, 3) and aovs["mis_weight"].shape == (24, 32)
    assert aovs["variance"].base is film and aovs["mis_weight"].base is film
    del film, aovs
    assert float(img.sum()) > 0  # the array keeps the film alive


@pytest.mark.parametrize("kw, name", [
    (dict(spp="many"), "spp"),
    (dict(heuristic="nonsense"), "heuristic"),
    (dict(light_pick="nearest"), "light_pick"),
    (dict(res="0x0"), "res"),
    (dict(res=(10, "x")), "res"),
    (dict(aovs=["depth"]), "aovs"),
    (dict(threads=[1, 2]), "threads"),
    (dict(frobnicate=1), "frobnicate"),
    (dict(max_depth=-3), "max_depth"),
    (dict(regularize="maybe"), "regularize"),
    (dict(guide=True, max_depth=1), "guide"),
    (dict(guide=True, max_depth=3, guide_alpha=2), "guide_alpha"),
    (dict(light_paths=True, max_depth=1), "light_paths"),
    (dict(light_paths="sometimes"), "light_paths"),
    (dict(spp=True, res="16x16"), "spp"),  # (a value option given True took the next flag as its value)
])
def test_bad_arguments_raise_value_error_naming_the_argument(cornell, kw, name):
    with pytest.raises(ValueError, match=name):
        cornell.render(**kw)


def test_a_broken_scene_raises_with_file_and_line(tmp_path):
    bad = tmp_path / "broken.pbrt"
    bad.write_text('Film "rgb" "integer xresolution" [ 32 ]\nWorldBegin\nShape "sphere" "float radius" [ 1\n'
                   'AttributeBegin\nMaterial "diffuse" "rgb reflectance" [ 0.5 0.5 ]\n')
    with pytest.raises(tuile.SceneError, match=r"broken\.pbrt:\d+") as e:
        tuile.load(str(bad))
    assert isinstance(e.value, ValueError)
    with pytest.raises(tuile.SceneError, match="missing.pbrt"):
        tuile.load(str(tmp_path / "missing.pbrt"))
    with pytest.raises(ValueError, match="path"):
        tuile.load(42)


def test_missing_images_warn_unless_strict(tmp_path):
    f = tmp_path / "tex.pbrt"
    f.write_text('WorldBegin\nTexture "c" "spectrum" "imagemap" "string filename" "gone.png"\n'
                 'Material "diffuse" "texture reflectance" "c"\n'
                 'Shape "trianglemesh" "point3 P" [ 1 0 0  0 1 0  0 0 1 ]\n')
    with pytest.warns(UserWarning, match=r"tex\.pbrt:2.*gone\.png"):
        scene = tuile.load(str(f))
    assert any("gone.png" in w for w in scene.warnings)
    with pytest.raises(tuile.SceneError, match=r"tex\.pbrt:2.*gone\.png"):
        tuile.load(str(f), strict=True)
    with pytest.raises(ValueError, match="strict"):
        scene.render(strict=True)


def test_paths_numpy_numbers_and_strict_are_taken_as_given(cornell, tmp_path):
    # pathlib.Path wherever a file is named; numpy's numbers as flags' values; strict a bool
    f = tmp_path / "tri.pbrt"
    f.write_text('WorldBegin\nLightSource "point" "rgb I" [ 1 1 1 ]\n'
                 'Shape "trianglemesh" "point3 P" [ 1 0 0  0 1 0  0 0 1 ]\n')
    scene = tuile.load(f)
    assert scene.source == str(f)
    with pytest.raises(ValueError, match="strict"):
        tuile.load(f, strict="no")  # (any non-empty string was True)
    a = cornell.render(spp=np.int64(2), res="16x12", seed=np.uint32(3),
                       rr_threshold=np.float32(0.25), quiet=np.bool_(True))
    b = cornell.render(spp=2, res="16x12", seed=3, rr_threshold=0.25)
    assert np.array_equal(a, b)
    tuile.write_exr(tmp_path / "a.exr", a)
    assert np.array_equal(tuile.read_exr(tmp_path / "a.exr"), a)
    with pytest.raises(ValueError, match="extension"):
        tuile.write_exr(tmp_path / "a.png", a)  # (an EXR named .png was written)
    (tmp_path / "d.exr").mkdir()
    with pytest.raises(ValueError, match="directory"):
        tuile.write_exr(tmp_path / "d.exr", a)
    with pytest.raises(ValueError, match="reference"):
        tuile.converge(cornell, strategies=["mis:power"], budget=0.1, reference=np.full(a.shape, np.nan, np.float32),
                       res="16x12", quiet=True)
    with pytest.raises(ValueError, match=r"\(use res\)"):  # (the keyword's name, not the flag's: --res)
        tuile.converge(cornell, strategies=["mis:power"], budget=0.1, reference=np.ones((5, 5, 3), np.float32),
                       res="16x12", quiet=True)


def test_info_is_what_tuile_info_prints(cornell):
    info = cornell.info()
    text = cli("info", "built-in:cornell").stdout
    assert info["scene"] == "built-in:cornell"
    assert info["resolution"] == (cornell.width, cornell.height)
    assert "triangles: %d\n" % info["triangles"] in text
    assert info["estimator"] in text and info["pipeline"] in text
    assert isinstance(info["features"], list) and isinstance(info["load"], float)
    assert cornell.info(res="20x10")["resolution"] == (20, 10)


def test_converge_gives_the_numbers_of_tuile_converge(tmp_path):
    ref = tmp_path / "ref.exr"
    cli("render", "built-in:two-panels", "--res", "32x24", "--spp", "256", "--seed", "7", "-o", ref, "--quiet")
    common = dict(res="32x24", spp_max=8, budget=600)
    cli("converge", "built-in:two-panels", "--res", "32x24", "--spp-max", "8", "--budget", "600", "--quiet",
        "--reference", ref, "--strategies", "bsdf,mis:power", "--csv", tmp_path / "c.csv")
    with open(tmp_path / "c.csv") as f:
        want = list(csv.DictReader(f))
    rows, images = tuile.converge(tuile.load("built-in:two-panels"), strategies=["bsdf", "mis:power"],
                                  reference=str(ref), images=True, **common)
    assert [(r["strategy"], r["spp"]) for r in rows] == [(w["strategy"], int(w["spp"])) for w in want]
    for r, w in zip(rows, want):
        assert r["mse"] == pytest.approx(float(w["mse"]), rel=1e-8)
        assert r["relmse"] == pytest.approx(float(w["relmse"]), rel=1e-8)
    assert set(images) == {"reference", "bsdf", "mis:power"} and images["bsdf"].shape == (24, 32, 3)
    # an array as the reference gives the same numbers
    again = tuile.converge("built-in:two-panels", strategies="bsdf", reference=tuile.read_exr(str(ref)), **common)
    assert [r["mse"] for r in again] == [r["mse"] for r in rows if r["strategy"] == "bsdf"]
    with pytest.raises(ValueError, match="strategies"):
        tuile.converge("built-in:two-panels", strategies=["light:nonsense"], **common)
    with pytest.raises(ValueError, match="budget"):
        tuile.converge("built-in:two-panels", strategies=["bsdf"], budget=-1)


def test_bench_and_profile_return_what_their_commands_print():
    b = tuile.bench("built-in:two-panels", spp=1, res="32x24", repeat=2, warmup=0)
    assert b["samples_per_second"]["median"] > 0 and len(b["runs_samples_per_second"]) == 2
    assert b["width"] == 32 and b["spp"] == 1 and b["peak_memory_bytes"] > 0
    p = tuile.profile(tuile.load("built-in:cornell"), spp=1, res="32x24", max_depth=3)
    stages = {s["stage"] for s in p["stages"]}
    assert {"scheduling"} < stages and len(p["stages"]) > 5
    assert p["samples_per_second"] > 0 and 0 <= p["embree_share"]["median"] <= 1
    assert len(p["vertices"]) >= 1 and "ns_per_path" in p["vertices"][0]
    with pytest.raises(ValueError, match="repeat"):
        tuile.bench("built-in:two-panels", repeat=0)


def test_a_render_releases_the_gil(cornell):
    import threading
    done = threading.Event()
    result = {}

    def work():
        result["img"] = cornell.render(spp=64, res="128x128", max_depth=5)
        done.set()

    t = threading.Thread(target=work)
    t.start()
    ticks = 0
    while not done.is_set():  # Python runs here while the render goes on
        ticks += 1
        done.wait(0.001)
    t.join()
    assert ticks > 20 and result["img"].shape == (128, 128, 3)


INTERRUPT = r"""
import os, signal, threading, time, sys
import tuile
scene = tuile.load("built-in:cornell")
sent = []
def interrupt():
    sent.append(time.monotonic())
    os.kill(os.getpid(), signal.SIGINT)
threading.Timer(0.5, interrupt).start()
try:
    scene.render(spp=1 << 20, res="256x256", max_depth=8)
    print("not interrupted")
except KeyboardInterrupt:
    print("stopped after %.3f s" % (time.monotonic() - sent[0]))
img = scene.render(spp=1, res="16x16")  # the interpreter and the scene still work
print("then rendered", img.shape)
"""


def test_keyboard_interrupt_stops_a_render_within_a_second():
    r = subprocess.run([sys.executable, "-c", INTERRUPT], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.split("\n")
    assert lines[0].startswith("stopped after"), r.stdout
    assert float(lines[0].split()[2]) < 1.0
    assert lines[1] == "then rendered (16, 16, 3)"


def test_plot_module_draws_with_matplotlib(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import tuile.plot
    rows = [dict(strategy=s, seconds=t, relmse=e / t) for s, e in (("a", 1.0), ("b", 0.5)) for t in (0.1, 0.2, 0.4)]
    ax = tuile.plot.error_vs_time(rows)
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    assert [line.get_label() for line in ax.get_lines()] == ["a", "b", "1/t"]
    x, y = ax.get_lines()[2].get_data()
    assert np.log(y[1] / y[0]) / np.log(x[1] / x[0]) == pytest.approx(-1.0)
    fig = tuile.plot.contact_sheet({"one": np.ones((8, 8, 3)), "half": np.full((8, 8, 3), 0.2140411)}, title="t")
    fig.savefig(tmp_path / "s.png")
    assert (tmp_path / "s.png").read_bytes()[:4] == b"\x89PNG"
    assert tuile.plot.srgb(np.array([0.0, 0.2140411, 1.0, 7.0])) == pytest.approx([0, 0.5, 1, 1], abs=1e-6)


def test_the_example_runs(tmp_path):
    out = tmp_path / "example.png"
    r = subprocess.run([sys.executable, os.path.join(SOURCE, "examples", "equal_time.py"), str(out), "0.2"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:4] == b"\x89PNG"
    assert r.stdout.count("relMSE") == 3
