"""tuile from Python: load a scene, render it into numpy arrays, measure estimators.

    import tuile
    scene = tuile.load("built-in:two-panels")       # or a pbrt-v4 file
    image = scene.render(spp=64, strategy="mis")    # (H, W, 3) float32, linear RGB
    rows = tuile.converge(scene, strategies=["light:solid-angle", "bsdf", "mis:power"], budget=2)

Every keyword argument of Scene.render is a flag of `tuile render` (light_pick="bvh" is
--light-pick bvh), parsed and checked by the same code, so the same flags give the same
bits as the command line. See docs/python.md; plots are in tuile.plot (matplotlib).
"""
import json as _json
import os as _os
import re as _re
import warnings as _warnings

from ._tuile import Film, Scene, SceneError, strategies  # noqa: F401
from ._tuile import __version__  # noqa: F401
from . import _tuile

__all__ = ["load", "Scene", "Film", "SceneError", "converge", "bench", "profile", "read_exr", "write_exr",
           "strategies", "plot"]


def load(path, strict=False):
    """Loads a pbrt-v4 scene (.pbrt, .pbrt.gz) or a built-in one ("built-in:two-panels",
    "built-in:cornell") and builds its BVH. A broken file raises tuile.SceneError (a
    ValueError) naming the file and line. What tuile approximates is given as warnings;
    strict=True is pbrt-v4's behaviour where tuile is lenient (an image texture that
    cannot be read is an error, not its constant mean with a warning)."""
    path = _path(path, "load")
    if not isinstance(strict, bool):  # (strict="no" was true)
        raise ValueError("load: strict: expected True or False, not %r" % (strict,))
    scene = Scene(path, strict=strict)
    for w in scene.warnings:
        _warnings.warn("tuile: " + w, stacklevel=2)
    return scene


def _path(path, where):
    """A file name given as a str or an os.PathLike (pathlib.Path), as a str."""
    if isinstance(path, str):
        return path
    if hasattr(path, "__fspath__"):
        p = _os.fspath(path)
        if isinstance(p, str):
            return p
    raise ValueError("%s: path: expected a file name (str or pathlib.Path) or 'built-in:NAME', not %s"
                     % (where, type(path).__name__))


def read_exr(path):
    """An EXR's RGB as an (H, W, 3) float32 array."""
    return _tuile.read_exr(_path(path, "read_exr"))


def write_exr(path, image):
    """Writes an (H, W, 3) array as an RGB float EXR (the name must end in .exr)."""
    _tuile.write_exr(_path(path, "write_exr"), image)


def _value(text):
    text = text.strip()
    if _re.fullmatch(r"-?\d+", text):
        return int(text)
    m = _re.fullmatch(r"(-?\d+(?:\.\d*)?(?:e[-+]?\d+)?) s", text)
    if m:
        return float(m.group(1))
    m = _re.fullmatch(r"(\d+)x(\d+)", text)
    if m:
        return (int(m.group(1)), int(m.group(2)))
    return text


_LISTS = {"sky", "approximation"}


def _info(self, **flags):
    """What `tuile info` prints, as a dict: numbers as numbers (times in seconds),
    the resolution as (W, H), features as a list, and the lines that repeat (sky,
    approximation) as lists."""
    out = {}
    for line in self._info(**flags).splitlines():
        key, sep, rest = line.partition(":")
        if not sep:
            continue
        key = key.strip()
        if key == "features":
            out[key] = rest.split()
        elif key in _LISTS:
            out.setdefault(key, []).append(rest.strip())
        else:
            out[key] = _value(rest)
    out.setdefault("approximation", [])
    return out


Scene.info = _info


def converge(scene, strategies=None, budget=10.0, reference=None, images=False, **flags):
    """Error against render time, as `tuile converge`: each strategy renders passes that
    double its samples until `budget` seconds are spent, and after each pass its relMSE
    against the reference is measured. Returns a list of rows (dicts: strategy, spp,
    seconds, mse, relmse, efficiency); with images=True, (rows, images) where images maps
    each strategy (and "reference") to its last image.

    strategies: names from tuile.strategies() (default: all); reference: None (one is
    rendered with mis:power and another seed), an EXR's path or an (H, W, 3) array; other
    keywords are `tuile converge`'s flags (spp_max, reference_spp, res, seed, ...)."""
    if isinstance(scene, str) or hasattr(scene, "__fspath__"):
        scene = load(scene)
    if not isinstance(scene, Scene):
        raise ValueError("converge: scene: expected a tuile.Scene or a path")
    if hasattr(reference, "__fspath__"):
        reference = _path(reference, "converge")
    return _tuile._converge(scene, strategies=strategies, reference=reference, images=images, budget=budget, **flags)


def _scene_source(scene, where):
    if isinstance(scene, Scene):
        return scene.source
    if isinstance(scene, str) or hasattr(scene, "__fspath__"):
        return _path(scene, where)
    raise ValueError(where + ": scene: expected a tuile.Scene or a path")


def bench(scene, **flags):
    """`tuile bench` (samples per second over repeated renders, time to first pixel, peak
    memory) as a dict: the figures `tuile bench --json` writes. Keywords: repeat, warmup
    and the render flags. The scene is loaded again (its load and BVH times are measured)."""
    return _json.loads(_tuile._bench(_scene_source(scene, "bench()"), **flags))


def profile(scene, **flags):
    """`tuile profile` (time per stage, Embree's share, per path vertex) as a dict: the
    figures `tuile profile --json` writes. Keywords: roofline, trace and the render flags."""
    return _json.loads(_tuile._profile(_scene_source(scene, "profile()"), **flags))


def __getattr__(name):  # tuile.plot without importing matplotlib for those who never plot
    if name == "plot":
        import importlib
        return importlib.import_module(".plot", __name__)
    raise AttributeError("module 'tuile' has no attribute %r" % name)
