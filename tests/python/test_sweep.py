"""Parameter sweeps (`dem ensemble SCENE --sweep TABLE`, or the scene's [sweep]): a 2-row x
2-packing sweep end to end on a tiny scene, each row an ordinary ensemble folder whose member 0 is
`dem run` with the row's value; the summary equal to the rows' own fit tables; resume after a kill;
bad tables refused before anything runs."""
import base64
import csv
import glob
import json
import os
import shutil
import subprocess
import time

import pytest

from conftest import DEM, kill_group, run_dem

TINY = """
[particles]
count = 150
seed = 11
[protocol]
target_phi = 0.64
compress_rate_tc = 3e-4
cycle_rate_tc = 2e-4
checkpoints_unloading = [0.74]
modes = ["D2"]
deviatoric_rate_tc = 6e-5
eps_d_max = 0.04
relax_ke_ratio = 1e-4
[integration]
dt_over_tc = 0.1
[output]
sample_strain = 0.002
vtk = false
[ensemble]
packings = 2
"""
TABLE = "# friction sweep\nname\tcontact.friction\nmu0\t0.0\nmu0.3\t0.3\n"
SCENE_SWEEP = '\n[sweep]\nkeys = ["contact.friction"]\nvalues = [[0.0], [0.3]]\nnames = ["mu0", "mu0.3"]\n'


def sweep(scene, table, out, *extra, check=True):
    args = ["ensemble", scene, "--out", out, *extra]
    return run_dem(*(args + (["--sweep", table] if table else [])), check=check, timeout=600)


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    (d / "tiny.toml").write_text(TINY)
    (d / "table.tsv").write_text(TABLE)
    t0 = time.time()
    p = sweep(d / "tiny.toml", d / "table.tsv", d / "run", "--cores", "2")
    return {"dir": d / "run", "scene": d / "tiny.toml", "table": d / "table.tsv", "stderr": p.stderr,
            "wall": time.time() - t0}


def rows_of(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_each_row_is_an_ordinary_ensemble_with_its_value(swept, tmp_path):
    run = swept["dir"]
    meta = json.loads((run / "sweep.json").read_text())
    assert meta["keys"] == ["contact.friction"] and [r["name"] for r in meta["rows"]] == ["mu0", "mu0.3"]
    for name in ("mu0", "mu0.3"):
        row = run / "rows" / name
        assert "[sweep]" not in (row / "scene.toml").read_text()
        assert (row / "fit" / "parameters.csv").exists() and (row / "ensemble" / "D2_phi0.740.csv").exists()
        assert len(glob.glob(str(row / "members" / "m00*" / "deviatoric" / "D2_phi0.740.csv"))) == 2
    # member 0 of row mu0.3 is `dem run` of the scene with that friction, bit for bit
    single = tmp_path / "single"
    run_dem("run", swept["scene"], "--out", single, "--set", "ensemble.packings=1", "--set", "contact.friction=0.3",
            "--threads", "1", "--quiet", check=True)
    a = (single / "deviatoric" / "D2_phi0.740.csv").read_bytes()
    assert a == (run / "rows" / "mu0.3" / "members" / "m000" / "deviatoric" / "D2_phi0.740.csv").read_bytes()
    assert a != (run / "rows" / "mu0" / "members" / "m000" / "deviatoric" / "D2_phi0.740.csv").read_bytes()
    # a row folder is reduced by `dem fit` like any ensemble folder
    again = run_dem("fit", run / "rows" / "mu0", "--force", "--no-plots")
    assert again.returncode == 0, again.stderr
    assert "sweep done in" in swept["stderr"], swept["stderr"][-2000:]


def test_summary_equals_the_rows_fit_tables(swept):
    run = swept["dir"]
    summary = rows_of(run / "sweep" / "parameters.csv")
    assert list(summary[0])[:5] == ["row", "contact.friction", "mode", "nu", "quantity"]
    assert len(summary) == 2 * 2   # 2 rows x (D2 at one nu) x (s_dev, F_dev)
    for s in summary:
        own = {(r["mode"], r["nu"], r["quantity"]): r for r in rows_of(run / "rows" / s["row"] / "fit" / "parameters.csv")}
        r = own[(s["mode"], s["nu"], s["quantity"])]
        for k in ("x_max", "se_x_max", "x_max_lo95", "x_max_hi95", "beta", "se_beta", "packings"):
            assert s[k] == r[k], (s["row"], k)
        assert s["contact.friction"] == {"mu0": "0.0", "mu0.3": "0.3"}[s["row"]]
    js = json.loads((run / "sweep" / "parameters.json").read_text())
    assert len(js["rows"]) == 4 and js["keys"] == ["contact.friction"]
    md = (run / "sweep" / "parameters.md").read_text()
    assert "`contact.friction`" in md and md.count("| mu0") == 4   # "| mu0 |" and "| mu0.3 |", two lines each


def test_summary_figure_has_no_empty_panel_and_carries_provenance(swept, tmp_path):
    from demkit import figures, sweep as sweep_mod
    run = tmp_path / "copy"
    shutil.copytree(swept["dir"], run, ignore=shutil.ignore_patterns("members"))
    figures.SAVED.clear()
    assert sweep_mod.main([str(run)]) == 0
    saved = [s for s in figures.SAVED if s["stem"].endswith("parameters_contact.friction")]
    assert saved and saved[0]["empty"] == 0 and saved[0]["axes"] >= 1
    png = (run / "sweep" / "parameters_contact.friction.png").read_bytes()
    assert b"dem-toolkit" in png and b"scene sha256:" in png
    assert (run / "sweep" / "parameters_contact.friction.svg").exists()


def test_scene_sweep_table_gives_the_same_rows(swept, tmp_path):
    """[sweep] in the scene and --sweep TABLE are one list: the same row scenes. (An unknown
    --profile stops the driver after the runner readied the folder, so nothing runs.)"""
    scene = tmp_path / "swept.toml"
    scene.write_text(TINY + SCENE_SWEEP)
    p = sweep(scene, None, tmp_path / "s", "--profile", "no-such-profile", check=False)
    assert p.returncode != 0 and "no Snakemake profile" in p.stderr
    for name in ("mu0", "mu0.3"):
        assert (tmp_path / "s" / "rows" / name / "scene.toml").read_text() == \
            (swept["dir"] / "rows" / name / "scene.toml").read_text()
    r = run_dem("run", scene, "--out", tmp_path / "x")
    assert r.returncode == 2 and "dem ensemble" in r.stderr and "[sweep]" in r.stderr
    r = sweep(scene, swept["table"], tmp_path / "both", check=False)
    assert r.returncode == 2 and "in one place" in r.stderr


@pytest.mark.parametrize("table, message", [
    ("contact.frction\n0.1\n0.2\n", "unknown key 'contact.frction'"),
    ("contact.friction\n0.1\n-0.5\n", "contact.friction"),
    ("name\tcontact.friction\na\t0.1\na\t0.2\n", "row name 'a' is also the name of"),
    ("name\tcontact.friction\na\t0.1\nb\t0.2\t7\n", "ragged row"),
    ("contact.friction\n0.1\n0.1\n", "same values as"),
    ("friction\n0.1\n", "must be a scene key section.key"),
    ("contact.friction\n", "no rows"),
])
def test_bad_tables_are_refused_before_anything_runs(tmp_path, table, message):
    (tmp_path / "tiny.toml").write_text(TINY)
    (tmp_path / "t.tsv").write_text(table)
    r = sweep(tmp_path / "tiny.toml", tmp_path / "t.tsv", tmp_path / "out", check=False)
    assert r.returncode == 2 and message in r.stderr, r.stderr
    assert not (tmp_path / "out").exists(), "a refused sweep must not touch --out"


def test_bad_scene_sweep_is_refused_by_every_command(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text(TINY + '\n[sweep]\nkeys = ["contact.friction"]\nvalues = [[0.1, 0.2]]\n')
    for args in (("info", scene, "--no-probe"), ("ensemble", scene, "--out", tmp_path / "o")):
        r = run_dem(*args)
        assert r.returncode == 2 and "the row has 2 values, the sweep 1 keys" in r.stderr, r.stderr


def finished(out):
    return {f: os.stat(f).st_mtime_ns for f in glob.glob(str(out / "rows" / "*" / "members" / "*" / "deviatoric" / "*.json"))}


def test_killed_sweep_resumes_without_redoing_finished_tasks(swept, tmp_path):
    out = tmp_path / "killed"
    p = subprocess.Popen([DEM, "ensemble", str(swept["scene"]), "--sweep", str(swept["table"]), "--out", str(out),
                          "--cores", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 300
    while time.time() < deadline and len(finished(out)) < 1:
        time.sleep(0.2)
    time.sleep(0.5)   # let Snakemake register the finished task
    kill_group(p)   # every process of the group gone, not only the leader
    inc = out / ".snakemake" / "incomplete"   # tasks Snakemake had not registered as finished: rerun, rightly
    marked = {os.path.join(str(out), base64.urlsafe_b64decode(m.name).decode())
              for m in inc.glob("*")} if inc.is_dir() else set()
    before = finished(out)
    assert set(before) - marked, "nothing finished before the kill"
    assert not (out / "sweep" / "parameters.csv").exists()
    r = sweep(swept["scene"], swept["table"], out, "--cores", "2")
    for f, t in before.items():
        if f not in marked:
            assert os.stat(f).st_mtime_ns == t, f"{f} was recomputed after the resume"
    assert "sweep done in" in r.stderr
    for f in sorted(glob.glob(str(swept["dir"] / "rows" / "*" / "ensemble" / "*.csv"))):
        rel = os.path.relpath(f, swept["dir"])
        assert (out / rel).read_bytes() == open(f, "rb").read(), rel
    assert (out / "sweep" / "parameters.csv").read_bytes() == (swept["dir"] / "sweep" / "parameters.csv").read_bytes()


def test_rerun_of_a_finished_sweep_does_nothing_and_another_sweep_is_refused(swept, tmp_path):
    t = {f: os.stat(f).st_mtime_ns for f in glob.glob(str(swept["dir"] / "rows" / "*" / "fit" / "*.csv"))}
    r = sweep(swept["scene"], swept["table"], swept["dir"])
    assert "sweep done in" in r.stderr
    assert t == {f: os.stat(f).st_mtime_ns for f in t}
    other = tmp_path / "other.tsv"
    other.write_text("name\tcontact.friction\nmu0\t0.0\nmu0.5\t0.5\n")
    r = sweep(swept["scene"], other, swept["dir"], check=False)
    assert r.returncode == 1 and "holds the results of another sweep" in r.stderr, r.stderr


def test_json_writer_writes_non_finite_numbers_as_null(tmp_path):
    from demkit.atomic import write_json_atomic
    f = tmp_path / "x.json"
    write_json_atomic(str(f), {"a": float("nan"), "b": [1.5, float("inf"), -float("inf")], "c": "s"})
    assert json.loads(f.read_text()) == {"a": None, "b": [1.5, None, None], "c": "s"}
    assert not (tmp_path / "x.json.part").exists()


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("sbatch") is None,
                    reason="needs root and Debian's slurm-wlm + munge (scripts/install-deps.sh) to start a Slurm")
def test_slurm_profile_gives_the_local_sweep(swept, tmp_path):
    from conftest import ROOT
    cluster = tmp_path / "slurm"
    script = os.path.join(ROOT, "scripts", "slurm-local.sh")
    start = subprocess.run(["bash", script, "start", str(cluster)], capture_output=True, text=True, timeout=120)
    assert start.returncode == 0, start.stderr
    try:
        env = {**os.environ, "SLURM_CONF": str(cluster / "slurm.conf"), "CI": "true"}   # CI: poll every 1 s
        out = tmp_path / "run"
        p = run_dem("ensemble", swept["scene"], "--sweep", swept["table"], "--out", out, "--profile", "slurm",
                    env=env, timeout=900)
        assert p.returncode == 0, p.stderr[-3000:]
        # Every packing went through sbatch (one job per packing when short tasks are grouped, one per task
        # otherwise), and every row's reduction.
        members = glob.glob(str(out / "rows" / "*" / "members" / "m*"))
        rows = glob.glob(str(out / "rows" / "*"))
        assert members and len(glob.glob(str(out / "logs" / "slurm" / "*.out"))) >= len(members) + len(rows), \
            "tasks did not go through sbatch"
        assert (out / "sweep" / "parameters.csv").read_bytes() == (swept["dir"] / "sweep" / "parameters.csv").read_bytes()
    finally:
        subprocess.run(["bash", script, "stop", str(cluster)], timeout=60)
