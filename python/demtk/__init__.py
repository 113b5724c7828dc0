"""demtk: the dem-toolkit engine from Python (docs/python.md).

    import demtk
    scene = demtk.load_scene("data/scenes/quickstart.toml", set={"contact.damping_kg_s": 0.5})
    state = demtk.read_checkpoint("runs/one/checkpoints/unloading_phi0.800.ckpt").state
    state.zero_strain()
    eng = demtk.Engine(scene, state)
    eng.step(1000, velocity_gradient=scene.velocity_gradient("D2"))
    m = eng.measure(); m["s_dev"], m.stress

SI units throughout, as in the C++ headers: m, kg, s, N, Pa; rates in 1/s.
The compiled part is demtk._core (pybind11, built by CMake into build/python/demtk/).
"""
import math
import os
from collections import namedtuple

from . import _core
from ._core import (BlowUp, Box, Engine, FitResult, Measurement, Scene, SceneError, State, column_table, curve_columns,
                    fit_saturating, format_paren, format_pm, random_packing, read_packing, run_mode, run_prep_stage,
                    run_protocol, run_stage, saturating)

__all__ = ["BlowUp", "Box", "Checkpoint", "Engine", "FitResult", "Measurement", "Scene", "SceneError", "State",
           "column_table", "contact_models", "curve_columns", "fit_curve", "fit_saturating", "format_paren", "format_pm",
           "load_scene", "random_packing", "read_checkpoint",
           "read_curve", "read_packing", "run_mode", "run_prep_stage", "run_protocol", "run_stage", "saturating",
           "scene_toml", "version"]

version = _core.version
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

Checkpoint = namedtuple("Checkpoint", "state scene_toml label")


def contact_models():
    """Every contact sub-model of the registry (the same as `dem info --contact-models --json`): a list of
    dicts with slot, name, title, selected_by, reference, keys (key, unit, default, bounds, meaning),
    history, rotations, column_groups (of demtk.column_table()), vtk_fields and the YADE and LAMMPS counterparts."""
    import json
    return json.loads(_core._contact_models_json())
Checkpoint.__doc__ = "A checkpoint read back: the State (bit-exact), the resolved scene text it was made with, its label."


# ---- scenes -----------------------------------------------------------------------------------

def _toml_value(v):
    """A Python value as a TOML literal (bool, int, float, str, list, dict -> inline table)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)   # shortest repr that round-trips: the same double
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if hasattr(v, "tolist"):   # numpy scalars and arrays
        return _toml_value(v.tolist())
    raise TypeError(f"cannot write {type(v).__name__} {v!r} as a scene value")


def _toml_key(k):
    k = str(k)
    return k if k and all(c.isalnum() or c in "_-" for c in k) else _toml_value(k)


def scene_toml(d):
    """A scene dict {section: {key: value}} as TOML text (sections as tables, nested dicts inline)."""
    out = []
    for section, body in d.items():
        if not isinstance(body, dict):
            raise SceneError(f"scene dict: '{section}' must be a section (a dict of keys), e.g. "
                             f"{{'contact': {{'damping_kg_s': 0.5}}}}")
        out.append(f"[{_toml_key(section)}]")
        out += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in body.items()]
    return "\n".join(out) + "\n"


def _overrides(set):
    if not set:
        return []
    if isinstance(set, dict):
        return [f"{k}={_toml_value(v)}" for k, v in set.items()]
    return list(set)   # already "section.key=value" strings, as on the command line


def load_scene(source=None, set=None, origin=None):
    """A validated Scene, as `dem` loads one.

    source: a path to a TOML file (str or os.PathLike), a dict {section: {key: value}}, a demtk.Scene
    (its resolved text is reloaded), or None (the built-in defaults). set: overrides as a dict
    {"section.key": value} or a list of "section.key=value" strings (the command line's --set).
    Raises demtk.SceneError with the C++ message (it names the key and the fix)."""
    ov = _overrides(set)
    if source is None:
        return _core._load_scene_text("", ov, origin or "defaults")
    if isinstance(source, dict):
        return _core._load_scene_text(scene_toml(source), ov, origin or "dict")
    if isinstance(source, Scene):
        return _core._load_scene_text(source.toml, ov, origin or source.origin)
    return _core._load_scene_file(os.fspath(source), ov)


def _scene_from_toml(text, set=None, origin="text"):
    """A Scene from TOML text."""
    return _core._load_scene_text(text, _overrides(set), origin)


Scene.from_toml = staticmethod(_scene_from_toml)


def _scene_to_dict(self):
    """The resolved scene as nested dicts (tomllib)."""
    import tomllib
    return tomllib.loads(self.toml)


def _scene_getitem(self, key):
    """scene["contact.damping_kg_s"]: a resolved key's value."""
    section, _, leaf = key.partition(".")
    d = self.to_dict()
    try:
        return d[section][leaf] if leaf else d[section]
    except KeyError:
        raise KeyError(key) from None


Scene.to_dict = _scene_to_dict
Scene.__getitem__ = _scene_getitem


# ---- files ------------------------------------------------------------------------------------

def read_checkpoint(path):
    """A `dem` checkpoint (.ckpt, validated, bit-exact) as Checkpoint(state, scene_toml, label)."""
    return Checkpoint(*_core._read_checkpoint(os.fspath(path)))


def _state_by_id(self, array):
    """A copy of a per-particle array (N, ...) with its rows in id order (row k = particle k)."""
    import numpy as np
    out = np.empty_like(array)
    out[self.ids] = array
    return out


State.by_id = _state_by_id

SceneError.__doc__ = ("A scene or packing `dem` would refuse (exit code 2): the message names the key or the "
                      "input and the fix. A ValueError.")
BlowUp.__doc__ = ("The run blew up (non-finite values, an overlap beyond max_overlap_fraction of a radius, "
                  "exploding kinetic energy; exit code 3 of `dem`): .last_good_state (a State or None) and, from "
                  "the stage runners, .checkpoint (the file the runner saved it to). A RuntimeError.")


def read_curve(path, frame=True):
    """A curve CSV (`dem` or yade_ref/) as a pandas DataFrame (frame=True) or a numpy record array.

    The '#' comment lines (column definitions, `# physics:` ...) go to .attrs["comments"] of the
    DataFrame; units are in the column names (_Pa, _J, _s; others dimensionless)."""
    import numpy as np
    import pandas as pd
    path = os.fspath(path)
    with open(path) as fh:
        comments = [ln.rstrip("\n") for ln in fh if ln.startswith("#")]
    try:   # pandas reads it; round_trip: each number exactly as written (not the fast parser, off in the last bit)
        df = pd.read_csv(path, comment="#", float_precision="round_trip", skip_blank_lines=True)
    except (pd.errors.EmptyDataError, pd.errors.ParserError) as e:
        raise ValueError(f"{path}: {e}") from None
    for name in ("step", "contacts"):
        if name in df and df[name].dtype.kind == "f":
            df[name] = df[name].astype(np.int64)
    header = list(df.columns)
    cols = {h: df[h].to_numpy() for h in header}
    if not frame:
        return np.rec.fromarrays([cols[h] for h in header], names=header)
    df.attrs["comments"] = comments
    df.attrs["path"] = path
    return df


def fit_curve(curve, column="s_dev", strain="eps_d", **options):
    """fit_saturating on a curve (a path, a DataFrame or a dict of arrays): `column` against `strain`.
    options as fit_saturating (eps_min, eps_max, loss, correct_autocorrelation, fix_x0)."""
    if isinstance(curve, (str, os.PathLike)):
        curve = read_curve(curve)
    return fit_saturating(list(map(float, curve[strain])), list(map(float, curve[column])), **options)


def _fit_as_dict(self):
    """The fit as a plain dict (corr as nested lists)."""
    keys = ["ok", "x0", "x_max", "beta", "se_x0", "se_x_max", "se_beta", "initial_slope", "se_initial_slope",
            "eps_95", "rmse", "r_squared", "cost", "residual_autocorrelation", "se_inflation", "n", "e_first",
            "e_last", "jacobian_rcond", "warnings", "usable", "not_usable_because"]
    d = {k: getattr(self, k) for k in keys}
    d["corr"] = self.corr.tolist()
    return d


FitResult.as_dict = _fit_as_dict


def _measurement_repr(self):
    c = self.columns
    return (f"<demtk.Measurement step={c['step']} eps_d={c['eps_d']:.4g} p={c['p_Pa']:.4g} Pa "
            f"s_dev={c['s_dev']:.4g} C={c['C']:.4g}>")


Measurement.__repr__ = _measurement_repr
