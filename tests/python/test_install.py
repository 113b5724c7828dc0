"""demtk and demkit install with pip from Debian's build tools, as Python users expect:
`pip install --no-build-isolation .` into a virtual environment (docs/python.md, "Installing"),
importable from anywhere, and every public function of demtk has a docstring."""
import inspect
import os
import shutil
import subprocess
import sys

import pytest

from conftest import ROOT


def test_pip_installs_demtk_and_demkit_into_a_venv(tmp_path):
    for mod in ("pip", "setuptools", "wheel", "venv"):
        if subprocess.run(["/usr/bin/python3", "-c", f"import {mod}"], capture_output=True).returncode:
            pytest.skip(f"Debian's python3-{mod} is not installed (scripts/install-deps.sh installs it)")
    venv = tmp_path / "venv"
    subprocess.run(["/usr/bin/python3", "-m", "venv", "--system-site-packages", str(venv)], check=True)
    py = str(venv / "bin" / "python")
    # The build folder scripts/setup.sh made: pip copies its extension instead of building another.
    env = dict(os.environ, DEMTK_BUILD_DIR=os.path.join(ROOT, "build"), PIP_NO_INDEX="1")
    env.pop("PYTHONPATH", None)
    p = subprocess.run([py, "-m", "pip", "install", "--no-build-isolation", ROOT], capture_output=True, text=True,
                       env=env, cwd=tmp_path, timeout=600)
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-3000:]
    probe = ("import demtk, demkit.rounding, os; "
             "s = demtk.load_scene({'particles': {'count': 50}}); "
             "print(os.path.dirname(demtk.__file__)); print(demkit.rounding.paren(0.196534, 0.00231554)); "
             "print(s.t_c > 0)")
    q = subprocess.run([py, "-c", probe], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert q.returncode == 0, q.stderr
    where, rounded, tc = q.stdout.split()
    assert where.startswith(str(venv)), where            # the installed copy, not the source tree
    assert rounded == "0.197(2)" and tc == "True"


def public_callables():
    """(name, object) of demtk's public functions, classes and their methods (properties aside)."""
    sys.path.insert(0, os.path.join(ROOT, "build", "python"))
    import demtk
    out = []
    for name, obj in vars(demtk).items():
        if name.startswith("_") or inspect.ismodule(obj):
            continue
        if inspect.isclass(obj) and obj.__module__.startswith("demtk"):
            out.append((name, obj))
            out += [(f"{name}.{m}", f) for m, f in vars(obj).items()
                    if not m.startswith("_") and callable(f) and not isinstance(f, type)]
        elif callable(obj) and getattr(obj, "__module__", "").startswith("demtk"):
            out.append((name, obj))
    return out


def doc_text(name, obj):
    """The docstring without pybind11's generated signature line."""
    lines = (getattr(obj, "__doc__", None) or "").strip().splitlines()
    if lines and lines[0].startswith(name.split(".")[-1] + "(") and ("->" in lines[0] or ": " in lines[0].split(")")[0]):
        lines = lines[1:]   # "step(self: demtk._core.Engine, n: int = 1, ...) -> int"
    return "\n".join(lines).strip()


def test_every_public_function_has_a_docstring():
    found = public_callables()
    assert len(found) > 30, found
    missing = [name for name, obj in found if not doc_text(name, obj)]
    assert not missing, "no docstring: " + ", ".join(missing)
    import demtk
    assert "[1/s]" in demtk.Engine.step.__doc__          # units given where a value has them
    assert "[m]" in demtk.Engine.contacts.__doc__
