"""Issue 32 (nothing lost, nothing silently wrong, part three): the Python module never lets a C++
fault kill the interpreter, Ctrl-C stops a run with its state intact, two threads cannot step one
State at once, and a NaN written from Python is named as such, not blamed on dt. Each class with
at least two spellings; the ones that used to kill the interpreter run in a child process."""
import fcntl
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from conftest import DEM, ROOT, run_dem

PYPATH = os.path.join(ROOT, "build", "python")
sys.path.insert(0, PYPATH)
import demtk  # noqa: E402

SMALL = {"particles": {"count": 200, "seed": 3}, "integration": {"threads": 1},
         "protocol": {"modes": ["D2"], "deviatoric_rate_tc": 1e-6, "eps_d_max": 1.0},
         "output": {"vtk": False}}


def child(code, timeout=120):
    """Runs `code` in a fresh interpreter with demtk importable; returns the CompletedProcess."""
    env = dict(os.environ, PYTHONPATH=PYPATH, OMP_WAIT_POLICY="passive")
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout, env=env, cwd=ROOT)


def small_state(scene, phi=0.3):
    return demtk.random_packing(scene, phi)


def lattice_state(scene, n=4, r=1e-3, gap=-0.01):
    """n^3 spheres of radius r on a cubic lattice, neighbours overlapping by -gap * r (a packing
    with contacts, built by hand)."""
    a = (2 + gap) * r
    g = (np.arange(n) + 0.5) * a
    pos = np.array([[x, y, z] for x in g for y in g for z in g])
    return demtk.State.from_arrays(pos, np.full(len(pos), r), [n * a] * 3, density=2000.0)


# ---- High 3: malformed sections and override paths through both Python doors ------------------

def test_malformed_sections_and_override_paths_raise_scene_error_never_crash():
    p = child(r'''
        import demtk
        bad_text = ["particles = 5\n", "[[contact]]\nstiffness_N_m = 1e5\n", "modes = [1, 0, -1]\n",
                    "protocol = 'x'\n", "[[particles]]\n[[particles]]\n"]
        bad_sets = [["contact..friction=0.5"], [".contact.friction=0.5"], ["contact.=0.5"], ['contact.""=0.5'],
                    ['" ".friction=0.5'], ["contact.a.b=1"], ["contact.friction=0.5\nparticles.count=5"]]
        n = 0
        for t in bad_text:
            try:
                demtk.Scene.from_toml(t)
            except demtk.SceneError as e:
                assert "must be a section" in str(e), (t, str(e)); n += 1
        for s in bad_sets:
            for load in (lambda: demtk.load_scene(set=s), lambda: demtk.Scene.from_toml("[particles]\ncount = 100\n", set=s)):
                try:
                    load()
                except demtk.SceneError as e:
                    assert "override" in str(e) and "section" in str(e), (s, str(e)); n += 1
        # spaces around the names are TOML's own: the key is read
        sc = demtk.load_scene(set=[" contact.friction=0.5"])
        assert 'friction = 0.5' in sc.toml
        print("refused", n)
    ''')
    assert p.returncode == 0, p.stderr[-3000:]
    assert "refused 19" in p.stdout, p.stdout + p.stderr


# ---- Ctrl-C while the engine steps with the GIL released ----------------------------------------

@pytest.mark.parametrize("call", ["run_mode", "run_stage", "step"])
def test_ctrl_c_stops_a_long_run_with_the_state_intact(call, tmp_path):
    p = child(f'''
        import math, os, signal, threading, time
        import numpy as np
        import demtk
        # A process started in the background by a non-interactive shell inherits SIGINT ignored, and
        # Python then installs no KeyboardInterrupt handler: what is tested is the handler's path.
        signal.signal(signal.SIGINT, signal.default_int_handler)
        sc = demtk.load_scene({SMALL!r})
        st = demtk.random_packing(sc, 0.3)
        threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
        t0 = time.monotonic()
        try:
            if "{call}" == "run_mode":
                demtk.run_mode(sc, st, "D2", out=r"{tmp_path}/d2.csv", check=False)
            elif "{call}" == "run_stage":
                demtk.run_stage(sc, st, "s", sc.velocity_gradient("D2"), "eps_d", target=1.0, out=r"{tmp_path}/s.csv")
            else:
                eng = demtk.Engine(sc, st)
                eng.step(4999, velocity_gradient=sc.velocity_gradient("D2"))   # under one signal-check chunk
                eng.step(10**9, velocity_gradient=sc.velocity_gradient("D2"))
            print("not interrupted")
        except KeyboardInterrupt:
            took = time.monotonic() - t0
            assert took < 30, took
            assert st.step > 0 and np.isfinite(st.positions).all() and np.isfinite(st.velocities).all()
            eng = demtk.Engine(sc, st)      # the state goes on
            before = st.step
            eng.step(10)
            assert st.step == before + 10
            print("interrupted after", round(took, 1), "s at step", before)
    ''', timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "interrupted after" in p.stdout, p.stdout + p.stderr


# ---- two threads on one State -------------------------------------------------------------------

def test_a_second_thread_is_refused_while_a_state_is_stepped():
    p = child(f'''
        import threading, time
        import demtk
        sc = demtk.load_scene({SMALL!r})
        st = demtk.random_packing(sc, 0.3)
        eng = demtk.Engine(sc, st)
        errors = []
        tried = threading.Event()

        def other(what):
            try:
                what()
                errors.append("accepted")
            except RuntimeError as e:
                errors.append(str(e))
            tried.set()

        # Spelling 1: while the first thread is stepping (GIL released), a step and a measure.
        t = threading.Thread(target=lambda: eng.step(200000, velocity_gradient=sc.velocity_gradient("D2")))
        t.start()
        while st.step == 0 and t.is_alive():      # stepping (with the GIL released) from here on
            time.sleep(0.01)
        time.sleep(0.05)
        other(lambda: eng.step(1)); other(lambda: eng.measure())
        other(lambda: demtk.Engine(sc, st).step(1))     # a second Engine on the same State
        t.join()
        # Spelling 2: from another thread while the first one sits in its callback.
        def callback(e):
            if not tried.is_set():
                threading.Thread(target=lambda: other(lambda: demtk.run_mode(sc, st, "D2", out="/dev/null", force=True))).start()
                tried.wait(30)
            return True
        tried.clear()
        eng.step(100, callback=callback, every=10)
        eng.step(5)                                     # free again: the first thread may go on
        print(len(errors), all("another thread" in e for e in errors), errors)
    ''', timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    assert p.stdout.startswith("4 True"), p.stdout + p.stderr


# ---- a NaN written from Python ------------------------------------------------------------------

def test_a_nan_written_through_a_view_is_named_not_blamed_on_dt(tmp_path):
    sc = demtk.load_scene(SMALL)
    st = small_state(sc)
    eng = demtk.Engine(sc, st)
    eng.step(5)
    good = st.copy()
    st.velocities[3, 1] = float("nan")            # spelling 1: through the writable view
    with pytest.raises(ValueError, match=r"velocities row 3 .*non-finite value written from Python") as e:
        eng.step(10)
    assert "dt" not in str(e.value)
    with pytest.raises(ValueError, match="velocities row 3"):
        demtk.run_mode(sc, st, "D2", out=str(tmp_path / "d2.csv"))
    assert not (tmp_path / "d2.csv.failed.ckpt").exists()
    st.velocities[3, 1] = 0.0
    eng.step(1)                                   # fixed: it goes on
    with pytest.raises(ValueError, match="non-finite"):   # spelling 2: set_velocities
        good.set_velocities(np.full(good.velocities.shape, np.inf))
    with pytest.raises(ValueError, match="non-finite"):   # spelling 3: set_positions
        pos = good.positions.copy(); pos[0, 0] = float("nan"); good.set_positions(pos)

    def poison(e):                                # spelling 4: inside a callback
        e.state.velocities[0, 0] = float("inf")
    with pytest.raises(ValueError, match="velocities row 0"):
        eng.step(100, callback=poison, every=10)
    assert st.step >= 16


# ---- a packing in tension: s_dev and the inertial number are not 0 ---------------------------

@pytest.mark.parametrize("gap_speed", [0.5, 2.0])
def test_s_dev_and_inertial_number_of_a_packing_in_tension(gap_speed):
    # Two overlapping spheres moving apart fast enough that the dashpot outpulls the spring
    # (allow_attractive): the contact pulls, p < 0. The ratios then use |p|.
    sc = demtk.load_scene({"particles": {"count": 2, "radius_min_m": 1e-3, "radius_max_m": 1e-3},
                           "contact": {"allow_attractive": True, "damping_kg_s": 30.0, "background_damping_kg_s": 0.0}})
    r, L = 1e-3, 1e-2
    pos = np.array([[4e-3, 5e-3, 5e-3], [6e-3 - 1e-7, 5e-3, 5e-3]])   # overlap 1e-7 m: k delta = 10 N < 30 N of dashpot
    vel = np.array([[-gap_speed, 0, 0], [gap_speed, 0, 0]])
    st = demtk.State.from_arrays(pos, [r, r], [L, L, L], density=2000.0, velocities=vel)
    eng = demtk.Engine(sc, st)
    grad = np.array([1e-3, 0.0, -1e-3])
    m = eng.measure(grad)
    p, sdev = m["p_Pa"], m["sigma_dev_Pa"]
    assert p < 0, p
    assert m["s_dev"] == pytest.approx(sdev / abs(p), rel=1e-12) and m["s_dev"] > 0
    expect_i = 1e-3 * 2 * r * np.sqrt(2000.0 / abs(p))
    assert m["inertial_number"] == pytest.approx(expect_i, rel=1e-12)



# ---- non-finite results are a blow-up naming the likely cause ----------------------------------

@pytest.mark.parametrize("contact", [{"normal": "luding", "luding_kp_N_m": 1e300},
                                     {"stiffness_N_m": 1e300, "damping_kg_s": 0.0}])
def test_a_non_finite_result_is_a_blow_up_naming_the_absurd_value(contact, tmp_path):
    sc = demtk.load_scene({**SMALL, "particles": {"count": 64, "radius_min_m": 1e-3, "radius_max_m": 1e-3},
                           "contact": contact, "protocol": {"modes": ["D2"], "eps_d_max": 0.01, "deviatoric_rate_tc": 1e-3}})
    st = lattice_state(sc, gap=-0.1)
    with pytest.raises(demtk.BlowUp) as e:
        demtk.run_mode(sc, st, "D2", out=str(tmp_path / "d2.csv"), check=False)
    key = "luding_kp_N_m" if "luding_kp_N_m" in contact else "stiffness_N_m"
    assert key in str(e.value) and "likely cause" in str(e.value) and "is inf" in str(e.value), str(e.value)
    assert not (tmp_path / "d2.csv").exists()     # no curve of infinities as a result


# ---- workflow folders -------------------------------------------------------------------------

ENS_SCENE = """
[particles]
count = 250
seed = 5
[protocol]
target_phi = 0.64
compress_rate_tc = 2e-4
cycle_rate_tc = 1e-4
checkpoints_unloading = [0.74]
modes = ["D2", "D3"]
deviatoric_rate_tc = 4e-5
eps_d_max = 0.06
[integration]
dt_over_tc = 0.1
[output]
sample_strain = 0.003
vtk = false
[ensemble]
packings = 3
"""


def fake_ensemble(tmp_path, with_curves=True):
    """An ensemble folder as `dem ensemble` leaves it (every planned task done), without running it."""
    out = tmp_path / "ens"
    out.mkdir()
    (out / "scene.toml").write_text(ENS_SCENE)
    tasks = json.loads(run_dem("info", out / "scene.toml", "--json", check=True).stdout)["tasks"]
    for t in tasks:
        f = out / t
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text('{"status": "complete"}\n')
        if with_curves and f.parent.name == "deviatoric":
            f.with_suffix(".csv").write_text("# a curve\n")
    for d in ("fit", "plots"):
        (out / d).mkdir()
        (out / d / "keep.txt").write_text("the ensemble's results\n")
    return out, tasks


@pytest.mark.parametrize("extra", [["--force"], [], ["--force", "--stages", "deviatoric"]])
def test_dem_run_refuses_an_ensemble_folder(tmp_path, extra):
    out, _ = fake_ensemble(tmp_path)
    scene = tmp_path / "one.toml"
    scene.write_text(ENS_SCENE.replace("packings = 3", "packings = 1"))
    p = run_dem("run", scene, "--out", out, "--quiet", *extra)
    assert p.returncode != 0 and "is an ensemble folder" in p.stderr, p.stderr
    assert (out / "fit" / "keep.txt").exists() and (out / "plots" / "keep.txt").exists()
    assert (out / "scene.toml").read_text() == ENS_SCENE
    (out / "sweep.json").write_text("{}")           # a sweep folder is named as such
    p = run_dem("run", scene, "--out", out, "--quiet", *extra)
    assert p.returncode != 0 and "is a sweep folder" in p.stderr, p.stderr


def test_a_member_curve_deleted_while_its_status_stays_is_not_done(tmp_path):
    out, tasks = fake_ensemble(tmp_path)
    gone = [t for t in tasks if t.endswith(".json") and "/deviatoric/" in t][:2]
    for t in gone:
        (out / t).with_suffix(".csv").unlink()
    # Spelling 1: the reduce (dem fit) does not fit one packing fewer.
    p = run_dem("fit", out, "--force", "--no-plots")
    assert p.returncode != 0 and "ensemble incomplete: 2 of" in p.stderr and "its curve is gone" in p.stderr, p.stderr
    # Spelling 2: the driver drops the orphaned status files, so that Snakemake reruns those tasks.
    from demkit import ensemble
    ensemble.drop_orphan_status(str(out), tasks)
    assert all(not (out / t).exists() for t in gone)
    assert all((out / t).exists() for t in tasks if t not in gone)
    assert ensemble.missing_tasks(str(out), tasks) == gone


def test_dem_model_out_onto_a_file_or_an_unwritable_folder(tmp_path):
    src = tmp_path / "ens"
    src.mkdir()
    f = tmp_path / "a_file"
    f.write_text("x")
    p = run_dem("model", src, "--out", f)
    assert p.returncode == 2 and "is a file, not a folder" in p.stderr, p.stderr
    assert f.read_text() == "x"
    p = run_dem("model", src, "--out", f / "sub")                       # under a file
    assert p.returncode == 2 and "cannot be created" in p.stderr, p.stderr
    p = run_dem("model", src, "--out", "/proc/dem_model_out")           # a read-only place, even for root
    assert p.returncode == 2 and ("cannot be created" in p.stderr or "not writable" in p.stderr), p.stderr
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        p = run_dem("model", src, "--out", ro)
        assert p.returncode == 2 and "not writable" in p.stderr, p.stderr


def snakemakes_in(out):
    """PIDs of running snakemake processes working on folder `out`."""
    pids = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                cmd = open(f"/proc/{d}/cmdline", "rb").read().split(b"\0")
            except OSError:
                continue
            if any(b"snakemake" in c for c in cmd) and str(out).encode() in cmd and b"--unlock" not in cmd:
                pids.append(int(d))
    return pids


def open_files(pid):
    """The paths of a process's open files; a descriptor closed while they are read is left out."""
    paths = []
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            paths.append(os.readlink(f"/proc/{pid}/fd/{fd}"))
        except FileNotFoundError:
            pass
    return paths


def lock_frees(path, seconds):
    """True as soon as an exclusive flock on `path` succeeds, within `seconds`."""
    deadline = time.time() + seconds
    with open(path) as fh:
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return True
            except BlockingIOError:
                if time.time() > deadline:
                    return False
                time.sleep(0.2)


def lock_holders(path):
    """The command lines of the processes that have `path` open."""
    out = []
    for d in filter(str.isdigit, os.listdir("/proc")):
        try:
            if path in open_files(d):
                out.append(open(f"/proc/{d}/cmdline", "rb").read().replace(b"\0", b" ").decode()[:200])
        except OSError:
            pass
    return out


@pytest.mark.skipif(not __import__("shutil").which("snakemake"), reason="snakemake is not installed")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killing_dem_ensemble_stops_its_snakemake(tmp_path, sig):
    scene = tmp_path / "ens.toml"
    scene.write_text(ENS_SCENE)
    out = tmp_path / "run"
    p = subprocess.Popen([DEM, "ensemble", str(scene), "--out", str(out), "--cores", "1"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not snakemakes_in(out):
            time.sleep(0.2)
        pids = snakemakes_in(out)
        assert pids, "Snakemake did not start"
        # Snakemake holds the folder lock itself: no second `dem ensemble` starts while it lives.
        lock = str(out / ".dem-ensemble.lock")
        assert lock in open_files(pids[0]), open_files(pids[0])
        p.send_signal(sig)                       # the driver only, not its process group
        p.wait(30)
        deadline = time.time() + 60
        while time.time() < deadline and snakemakes_in(out):
            time.sleep(0.2)
        assert not snakemakes_in(out), "Snakemake outlived the killed `dem ensemble`"
        # and the lock is free for the rerun once Snakemake's last descendants have gone (a child it
        # forked while it was stopping may hold the descriptor for a moment: once CI caught one)
        assert lock_frees(lock, 30), f"{lock} still locked 30 s after Snakemake ended; held by {lock_holders(lock)}"
    finally:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_a_snakemake_that_ignores_sigterm_is_killed_after_its_grace(tmp_path):
    """`dem ensemble` stopped by SIGTERM gives Snakemake demkit.ensemble.STOP_GRACE_S to stop, then kills it: a stand-in
    `snakemake` on PATH that ignores SIGTERM does not keep the driver (or the folder lock) alive."""
    from demkit import ensemble
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "snakemake").write_text("#!/bin/sh\ntrap '' TERM\nwhile :; do sleep 0.2; done\n")
    (fake / "snakemake").chmod(0o755)
    scene = tmp_path / "ens.toml"
    scene.write_text(ENS_SCENE)
    out = tmp_path / "run"
    env = dict(os.environ, PATH=f"{fake}:{os.environ['PATH']}")
    p = subprocess.Popen([DEM, "ensemble", str(scene), "--out", str(out), "--cores", "1"], stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True, start_new_session=True, env=env)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not snakemakes_in(out):
            time.sleep(0.2)
        assert snakemakes_in(out), "the stand-in Snakemake did not start"
        time.sleep(1.0)   # the driver's handlers are set once Snakemake has started
        t0 = time.time()
        p.send_signal(signal.SIGTERM)
        err = p.communicate(timeout=ensemble.STOP_GRACE_S + 30)[1]
        took = time.time() - t0
        assert p.returncode == 130, err
        assert f"Snakemake did not stop within {ensemble.STOP_GRACE_S} s of SIGTERM; killed" in err, err
        assert ensemble.STOP_GRACE_S - 1 < took < ensemble.STOP_GRACE_S + 30
        deadline = time.time() + 10
        while time.time() < deadline and snakemakes_in(out):
            time.sleep(0.2)
        assert not snakemakes_in(out)
        assert lock_frees(str(out / ".dem-ensemble.lock"), 10)
    finally:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_empty_arrays_into_an_empty_state_copy_nothing_and_do_not_crash():
    # fuzz_demtk under UBSan (tests/SANITIZE.md): a (0, 3) array copied into a state of no particles
    # passed vector::data() == nullptr to memcpy (undefined behaviour; the sanitizer build aborts the
    # interpreter). Spellings: from_arrays with empty positions, velocities and ids; set_positions and
    # set_velocities of empty rows; each either gives a state of 0 particles or a clear Python error.
    e3, e1 = np.zeros((0, 3)), np.zeros(0)
    for kw in ({}, {"velocities": e3}, {"ids": np.zeros(0, dtype=np.int32)}, {"velocities": e3, "ids": []}):
        try:
            st = demtk.State.from_arrays(e3, e1, [0.01, 0.01, 0.01], density=2000.0, **kw)
        except (ValueError, RuntimeError) as err:
            assert str(err)
            continue
        assert st.count == 0
        st.set_positions(e3)
        st.set_velocities(e3)


def test_an_error_that_underflows_next_to_its_value_is_formatted_not_cast_from_minus_inf():
    # fuzz_demtk under UBSan: round_to_error scaled 5e-324 by 1e-308 to 0 and cast floor(log10(0)) = -inf
    # to int (undefined behaviour). Such an error is far below the value's precision: the value is
    # written to 15 digits, as when the rounded value exceeds 1e15.
    for v, e in ((1e308, 5e-324), (-1e308, 5e-324), (1e300, 1e-320), (2e5, 5e-324)):
        for fmt in (demtk.format_paren, demtk.format_pm):
            s = fmt(v, e)
            assert isinstance(s, str) and s.lstrip("(-")[:1] in ("1", "2"), (v, e, s)
    # Powers of ten that underflow (an error or a value below 1e-290): written unrounded, no cast of inf.
    for v, e in ((0.0, 5e-324), (5e-324, 1e-300), (1e-300, 5e-324), (-3e-295, 2e-300)):
        for fmt in (demtk.format_paren, demtk.format_pm):
            s = fmt(v, e)
            assert isinstance(s, str) and s and "inf" not in s, (v, e, s)


def test_a_state_far_outside_its_cells_is_binned_without_casting_inf_to_int():
    # fuzz_demtk under UBSan: the neighbour list's cell index cast x / cell_size = inf to int (a box of
    # 1e-300 m, a position of 1e308 m). Each spelling is refused with a Python error or builds an engine.
    cases = [([[0, 0, 0], [1e308, 0, 0]], [1e-3, 1e-3], [0.01] * 3),
             ([[0, 0, 0], [-1e308, 1e308, 0]], [1e-3, 1e-3], [0.01] * 3),
             ([[0, 0, 0], [1e-301, 0, 0]], [1e-302, 1e-302], [1e-300] * 3)]
    for pos, rad, box in cases:
        try:
            st = demtk.State.from_arrays(np.array(pos, float), np.array(rad, float), box, density=2000.0)
            demtk.Engine(demtk.load_scene(None, set={"particles.count": 2, "integration.threads": 1}), st)
        except (demtk.SceneError, demtk.BlowUp, ValueError, RuntimeError) as err:
            assert str(err)
