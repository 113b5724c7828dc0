"""Every .tex table the toolkit writes compiles, and fits an A4 page (2.5 cm margins) at \\small.

Skipped where LaTeX is not installed (`bash scripts/install-deps.sh --tex` installs pdflatex,
booktabs and siunitx: about 135 MB). The tables: a single run's fit (the pipeline's small run), an
ensemble's fit with the peak law's columns (a copy of the stored data/friction_n1000/mu_0.3,
refitted), and `dem model`'s tables on it."""
import re
import shutil
import subprocess

import pytest

from conftest import ROOT, run_dem

pytestmark = pytest.mark.skipif(shutil.which("pdflatex") is None,
                                reason="no pdflatex (bash scripts/install-deps.sh --tex installs LaTeX)")

DOC = r"""\documentclass[a4paper]{article}
\usepackage[margin=2.5cm]{geometry}
\usepackage{booktabs,siunitx}
\begin{document}
\small
\input{%s}
\end{document}
"""


def compile_table(tex, work):
    """(ok, how much too wide in pt (0 when it fits), the log's error lines)."""
    doc = work / (tex.parent.name + "_" + tex.stem + "_doc.tex")
    doc.write_text(DOC % tex.as_posix())
    p = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", doc.name], cwd=work,
                       capture_output=True, text=True, timeout=120)
    log = doc.with_suffix(".log").read_text(errors="replace")
    over = [float(x) for x in re.findall(r"Overfull \\hbox \(([0-9.]+)pt too wide\)", log)]
    errors = [ln for ln in log.splitlines() if ln.startswith("!")]
    return p.returncode == 0, max(over, default=0.0), errors


@pytest.fixture(scope="module")
def ensemble_fit(tmp_path_factory):
    d = tmp_path_factory.mktemp("texfit") / "mu_0.3"
    shutil.copytree(f"{ROOT}/data/friction_n1000/mu_0.3", d)
    run_dem("fit", d, "--force", "--no-plots", check=True, timeout=600)
    run_dem("model", d, "--no-jackknife", "--no-plots", check=True, timeout=600)
    return d


def test_every_table_compiles_and_fits_a4(small_run, ensemble_fit, tmp_path):
    tables = sorted((small_run["dir"] / "fit").glob("*.tex")) + sorted((ensemble_fit / "fit").glob("*.tex")) + \
        sorted((ensemble_fit / "model").glob("*.tex")) + sorted((ensemble_fit / "ensemble").glob("*.tex"))
    names = {t.name for t in tables}
    assert {"parameters.tex", "nu_laws.tex", "isotropic.tex", "shared_path.tex"} <= names, names
    bad, wide = [], []
    for t in tables:
        ok, over, errors = compile_table(t, tmp_path)
        if not ok:
            bad.append(f"{t}: {errors[:3]}")
        # the tables for people must fit; the machine dumps of `dem model` are for reading, not printing
        elif over > 1.0 and t.parent.name == "fit":
            wide.append(f"{t}: {over:.0f} pt too wide")
    assert not bad, "\n".join(bad)
    assert not wide, "\n".join(wide)
