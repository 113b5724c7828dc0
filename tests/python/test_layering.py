"""The include layering of ARCHITECTURE.md (issue 34): no folder of sim/ includes a higher one, and
no header private to a folder (sim/src/X/*.hpp) is read from another; scripts/include_graph.py
draws the graph from the sources' #include lines."""
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCRIPT = os.path.join(ROOT, "scripts", "include_graph.py")


def test_no_folder_includes_a_higher_one():
    p = subprocess.run([sys.executable, SCRIPT], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert "stages   -> io" in p.stdout and "AGAINST" not in p.stdout


def test_the_check_sees_an_arrow_against_the_layering(tmp_path):
    # A copy of the script run on a tree with one back-running include must fail, naming it.
    for d in ("scripts", "sim/src/core", "sim/src/stages", "sim/include/dem/stages", "sim/include/dem/core"):
        os.makedirs(tmp_path / d)
    (tmp_path / "scripts" / "include_graph.py").write_text(open(SCRIPT).read())
    (tmp_path / "sim/include/dem/stages/runner.hpp").write_text("#pragma once\n")
    (tmp_path / "sim/src/core/model.cpp").write_text('#include "dem/stages/runner.hpp"\n')
    (tmp_path / "sim/src/stages/private.hpp").write_text("#pragma once\n")
    (tmp_path / "sim/include/dem/core/model.hpp").write_text('#include "stages/private.hpp"\n')
    p = subprocess.run([sys.executable, str(tmp_path / "scripts" / "include_graph.py")], capture_output=True,
                       text=True)
    assert p.returncode == 1
    assert "sim/src/core/model.cpp -> sim/include/dem/stages/runner.hpp: core/ includes the higher stages/" in p.stderr
    assert "a header private to stages/ read from core/" in p.stderr
