"""Driver of the ensemble workflow (workflow/Snakefile): runs Snakemake on a results folder,
shows progress with the time left, and keeps Snakemake's own log in DIR/logs/snakemake.log.

Called by `dem ensemble SCENE --out DIR` after the runner has validated the scene and written
DIR/scene.toml (or, for a parameter sweep, DIR/sweep.json and DIR/rows/NAME/scene.toml: one
ensemble per row, then the summary of demkit.sweep); by hand:
    python3 -m demkit.ensemble DIR [--cores N] [--profile slurm]

Progress is measured from the files the tasks leave (status JSONs), weighted by each task's
estimated particle-steps from `dem info --json`, so it reads the same on one machine and on a
cluster.
"""
import argparse
import fcntl
import glob
import json
import os
import shutil
import signal
import subprocess
import sys
import time

from demkit import breakdown

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SNAKEFILE = os.path.join(REPO, "workflow", "Snakefile")
PROFILES = os.path.join(REPO, "workflow", "profiles")


def load_plan(dem, out):
    r = subprocess.run([dem, "info", os.path.join(out, "scene.toml"), "--json"], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"dem ensemble: {r.stderr.strip()}")
    return json.loads(r.stdout)


def read_sweep(out):
    """DIR/sweep.json (written by `dem ensemble --sweep` or a scene's [sweep]), or None."""
    path = os.path.join(out, "sweep.json")
    if not os.path.exists(path):
        return None
    with open(path) as fh:
        return json.load(fh)


def load_plans(dem, out):
    """[(base, plan)]: ("", plan) for an ensemble folder, ("rows/NAME/", plan) per row of a sweep
    (the prefix of the row's files relative to DIR)."""
    sweep = read_sweep(out)
    bases = [r["folder"] + "/" for r in sweep["rows"]] if sweep else [""]
    return sweep, [(b, load_plan(dem, os.path.join(out, b))) for b in bases]


def task_weights(plan, base=""):
    """{status file relative to DIR: particle-steps} for every task of the plan."""
    w = {}
    for m in plan["members"]:
        w[f"{base}members/{m['name']}/prep.json"] = plan["prep_particle_steps"]
        for c in plan["checkpoints"]:
            phi = c["stem"].rsplit("_", 1)[1]   # the series may hold '_' (cycle_unloading_phi0.800)
            for mode in plan["modes"]:
                w[f"{base}members/{m['name']}/deviatoric/{mode}_{phi}.json"] = plan["mode_particle_steps"][mode]
    return w


def all_weights(plans):
    w = {}
    for base, plan in plans:
        w.update(task_weights(plan, base))
    return w


def planned_tasks(plans):
    return [base + t for base, plan in plans for t in (plan.get("tasks") or list(task_weights(plan)))]


def fmt_time(s):
    s = int(round(s))
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s"


class Progress:
    def __init__(self, out, weights, stream=sys.stderr, what="ensemble"):
        self.out, self.weights, self.stream, self.what = out, weights, stream, what
        self.total = sum(weights.values())
        self.t0 = time.time()
        self.done0 = self.done_weight()[1]   # work finished by an earlier run (resume)
        self.tty = stream.isatty()
        self.last_line = ""
        self.last_n, self.last_print = -1, 0.0

    def done_weight(self):
        n, w = 0, 0.0
        for f, wt in self.weights.items():
            if os.path.exists(os.path.join(self.out, f)):
                n += 1
                w += wt
        return n, w

    def line(self):
        n, w = self.done_weight()
        el = time.time() - self.t0
        new = w - self.done0
        frac = w / self.total if self.total else 1.0
        left = el * (self.total - w) / new if new > 0 else float("nan")
        eta = f"~{fmt_time(left)} left" if new > 0 and w < self.total else ("reducing" if w >= self.total else "estimating")
        return f"[{self.what}] {n}/{len(self.weights)} tasks, {100 * frac:3.0f}% of the work, {fmt_time(el)} elapsed, {eta}"

    def show(self, final=False):
        ln = self.line()
        n = self.done_weight()[0]
        if self.tty:
            self.stream.write("\r" + ln.ljust(len(self.last_line)) + ("\n" if final else ""))
        elif final or n != self.last_n or time.time() - self.last_print >= 60:
            self.stream.write(ln + "\n")
            self.last_n, self.last_print = n, time.time()
        self.stream.flush()
        self.last_line = ln


def snakemake_command(out, dem, cores, profile, extra, group="auto"):
    cmd = ["snakemake", "-s", SNAKEFILE, "-d", out, "--config", f"dem={dem}", f"python={sys.executable}",
           f"group={group}", "--scheduler", "greedy", "--rerun-incomplete", "--keep-going", "--printshellcmds", "--nocolor"]
    if profile:
        path = profile if os.sep in profile else os.path.join(PROFILES, profile)
        if not os.path.isdir(path):
            sys.exit(f"dem ensemble: no Snakemake profile '{profile}' (shipped: "
                     f"{', '.join(sorted(os.listdir(PROFILES)))}; or give a folder with a config.yaml)")
        cmd += ["--profile", path]
    if cores:
        cmd += ["--cores", str(cores)]
    elif not profile:
        cmd += ["--cores", str(os.cpu_count() or 1)]
    return cmd + list(extra)


SLURM_HINT = ("on a cluster, run `dem ensemble` where `sinfo` works (a login node), or point SLURM_CONF at the "
              "cluster's slurm.conf; to try Slurm on this machine (as root): "
              "eval \"$(bash scripts/slurm-local.sh start /tmp/slurm)\" (it starts a one-node Slurm and sets SLURM_CONF)")


def slurm_preflight(timeout=20):
    """None when sbatch is installed and a Slurm controller answers (`sinfo`), else the reason,
    naming SLURM_CONF and how to set it."""
    if shutil.which("sbatch") is None:
        return "sbatch is not installed (Debian package slurm-wlm; scripts/install-deps.sh installs it); " + SLURM_HINT
    conf = os.environ.get("SLURM_CONF")
    where = f"SLURM_CONF={conf}" if conf else "SLURM_CONF is not set (so Slurm looks for /etc/slurm/slurm.conf, then DNS)"
    if conf and not os.path.isfile(conf):
        return f"{where}, but there is no such file; " + SLURM_HINT
    try:
        r = subprocess.run(["sinfo", "-h", "-o", "%P"], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return f"no Slurm controller answered within {timeout} s ({where}); " + SLURM_HINT
    err = " ".join(r.stderr.split())
    if r.returncode != 0 or not r.stdout.strip():
        return f"no Slurm controller reachable ({where}; sinfo: {err[:200] or 'no partitions'}); " + SLURM_HINT
    return None


def uses_slurm(profile):
    path = profile if os.sep in profile else os.path.join(PROFILES, profile)
    try:
        with open(os.path.join(path, "config.yaml")) as fh:
            return "sbatch" in fh.read() or "slurm" in profile
    except OSError:
        return "slurm" in profile


def hold_folder_lock(out, dem):
    """Hold DIR/.dem-ensemble.lock for the life of this process (the kernel drops it when the
    process dies, however it dies). Holding it proves no other `dem ensemble` works on DIR, so a
    Snakemake lock left behind by a killed run is stale and can be removed."""
    inherited = os.environ.pop("DEM_ENSEMBLE_LOCK_FD", "")
    if inherited:   # `dem ensemble` took the lock before it touched DIR and passed it on
        fh = os.fdopen(int(inherited), "r+")
    else:
        fd = os.open(os.path.join(out, ".dem-ensemble.lock"), os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        fh = os.fdopen(fd, "r+")
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        sys.exit(f"dem ensemble: another `dem ensemble` is running on {out}; wait for it, or stop it first")
    locks = glob.glob(os.path.join(out, ".snakemake", "locks", "*"))
    if locks:
        sys.stderr.write("dem ensemble: removing the lock of an interrupted earlier run\n")
        subprocess.run(["snakemake", "-s", SNAKEFILE, "-d", out, "--unlock", "--config", f"dem={dem}"],
                       capture_output=True)
    return fh


def main(argv=None):
    ap = argparse.ArgumentParser(description="run the ensemble workflow on a results folder")
    ap.add_argument("out", help="results folder holding scene.toml (written by `dem ensemble`)")
    ap.add_argument("--dem", default=os.path.join(REPO, "build", "dem"), help="the dem executable")
    ap.add_argument("--cores", type=int, default=0, help="parallel single-threaded tasks (default: all cores)")
    ap.add_argument("--profile", default="", help="Snakemake profile: 'slurm' (shipped) or a folder")
    ap.add_argument("--group", default="auto", choices=("auto", "member", "task"),
                    help="a packing's tasks as one Snakemake job: auto (when short), member (always), task (never)")
    ap.add_argument("--progress-seconds", type=float, default=5.0)
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = argv[argv.index("--") + 1:] if "--" in argv else []   # after --: more Snakemake arguments
    a = ap.parse_args(argv[:len(argv) - len(extra) - (1 if "--" in argv else 0)])
    if shutil.which("snakemake") is None:
        sys.exit("dem ensemble: snakemake is not installed (Debian package 'snakemake'; scripts/install-deps.sh installs it)")
    t0 = breakdown.process_start_time() or time.time()   # `dem ensemble` execs this driver: its start
    out = os.path.abspath(a.out)
    dem = os.path.abspath(a.dem)
    sweep, plans = load_plans(dem, out)
    if a.profile and uses_slurm(a.profile):
        why = slurm_preflight()
        if why:
            sys.stderr.write(f"dem ensemble: --profile {a.profile}: {why}\n")
            return 2
    lock = hold_folder_lock(out, dem)  # noqa: F841 (held until exit)
    os.makedirs(os.path.join(out, "logs", "slurm"), exist_ok=True)   # sbatch --output needs the folder
    log_path = os.path.join(out, "logs", "snakemake.log")
    env = dict(os.environ)
    env["PYTHONPATH"] = REPO + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.setdefault("OMP_WAIT_POLICY", "passive")   # single-threaded tasks: never spin on shared cores
    tasks = planned_tasks(plans)
    drop_orphan_status(out, tasks)
    drop_stale_results(out, plans, sweep)
    drop_stale_groups(out, plans)
    final = os.path.join(out, "sweep" if sweep else "fit", "parameters.csv")
    if a.profile and "slurm" in os.path.basename(os.path.normpath(a.profile)):
        check_slurm()
    prog = Progress(out, all_weights(plans), what="sweep" if sweep else "ensemble")
    plan = plans[0][1]
    rows = f"{len(plans)} rows ({', '.join(sweep['keys'])}) x " if sweep else ""
    sys.stderr.write(f"dem ensemble: {rows}{plan['packings']} packings x {len(plan['checkpoints'])} volume fractions x "
                     f"{len(plan['modes'])} modes = {len(prog.weights)} tasks + "
                     f"{f'{len(plans)} reduces + summary' if sweep else 'reduce'}, "
                     f"{prog.total / 1e9:.1f}e9 particle-steps (estimated); Snakemake log: {log_path}\n")
    cmd = snakemake_command(out, dem, a.cores, a.profile, extra, a.group)
    with open(log_path, "a") as log:
        log.write(f"\n=== {time.strftime('%Y-%m-%d %H:%M:%S')} {' '.join(cmd)}\n")
        log.flush()
        # Snakemake holds the folder lock too (a rerun cannot start a second one while it lives),
        # and gets SIGTERM when this process dies, however it dies (SIGKILL included).
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, pass_fds=(lock.fileno(),),
                                preexec_fn=die_with_parent)
        stop_on = {sig: signal.signal(sig, _raise_interrupt) for sig in (signal.SIGTERM, signal.SIGHUP)}
        try:
            while proc.poll() is None:
                prog.show()
                try:
                    proc.wait(timeout=a.progress_seconds)
                except subprocess.TimeoutExpired:
                    pass
        except KeyboardInterrupt:
            stop_snakemake(proc, STOP_GRACE_PROFILE_S if a.profile else STOP_GRACE_S)
            prog.show(final=True)
            sys.stderr.write("dem ensemble: interrupted; run the same command again to continue where it stopped\n")
            return 130
        finally:
            for sig, old in stop_on.items():
                signal.signal(sig, old)
    prog.show(final=True)
    if proc.returncode != 0:
        return explain_failure(out, plans, log_path, proc.returncode, a.profile)
    missing = missing_tasks(out, tasks)
    if missing or not os.path.exists(final):
        what = (f"{len(missing)} of {len(tasks)} planned tasks have no result ({', '.join(missing[:3])}"
                f"{', ...' if len(missing) > 3 else ''})") if missing else \
            f"the {'summary' if sweep else 'reduce'} wrote no {os.path.relpath(final, out)}"
        sys.stderr.write(f"dem ensemble: Snakemake ended without error, but the ensemble is incomplete: {what}; "
                         f"nothing is reported as done: run the same command again to continue (logs: {out}/logs)\n")
        return 1
    for base, _ in plans:
        report_members(os.path.join(out, base), base)
    breakdown.report(out, plans, t0, a.cores or (1 if a.profile else os.cpu_count() or 1), sys.stderr)
    if sweep:
        sys.stderr.write(f"dem ensemble: sweep done in {fmt_time(time.time() - prog.t0)}: summary (fitted parameters "
                         f"against {', '.join(sweep['keys'])}) in {out}/sweep; each row's ensemble in {out}/rows/NAME "
                         "(ensemble/, fit/, plots/)\n")
        return 0
    sys.stderr.write(f"dem ensemble: done in {fmt_time(time.time() - prog.t0)}: averages in {out}/ensemble, "
                     f"fit tables in {out}/fit, plots in {out}/plots\n")
    return 0


# Seconds Snakemake gets to stop after SIGTERM (it stops its jobs and marks their outputs incomplete; with a profile
# it cancels the cluster's jobs, which takes longer) before it is killed: once CI caught it still alive 30 s after.
STOP_GRACE_S = 15
STOP_GRACE_PROFILE_S = 120


def stop_snakemake(proc, grace):
    """SIGTERM to Snakemake; SIGKILL if it has not ended within `grace` seconds (said on stderr). A killed
    Snakemake leaves its incomplete markers, which the rerun's --rerun-incomplete redoes."""
    proc.terminate()
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        sys.stderr.write(f"dem ensemble: Snakemake did not stop within {grace} s of SIGTERM; killed\n")
        proc.kill()
        proc.wait()


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt   # SIGTERM, SIGHUP: stop Snakemake as Ctrl-C does


def die_with_parent():
    """In the Snakemake child: SIGTERM when its parent (this driver) dies (Linux prctl PR_SET_PDEATHSIG)."""
    try:
        import ctypes
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)
    except (OSError, AttributeError):
        pass


def drop_orphan_status(out, tasks):
    """A mode task whose status says complete while its curve is gone (deleted by hand) is not done:
    its status file goes, so that Snakemake runs the task again (and the reduce after it)."""
    for t in tasks:
        if not (t.endswith(".json") and os.path.basename(os.path.dirname(t)) == "deviatoric"):
            continue
        path = os.path.join(out, t)
        st = read_status(path) if os.path.exists(path) else None
        csv_path = path[:-len(".json")] + ".csv"
        if st and st.get("status") == "complete" and not os.path.exists(csv_path):
            sys.stderr.write(f"dem ensemble: {os.path.relpath(csv_path, out)} is gone although its status file says "
                             "complete: that task is run again\n")
            os.unlink(path)


def drop_stale_results(out, plans, sweep):
    """Fit tables written while tasks were missing (`dem fit --partial`, a copy, an older plan) must
    not stand for the ensemble: the reduce writes them again once every task is done; so is a
    sweep's summary while any row is unfinished."""
    unfinished = 0
    for base, plan in plans:
        tasks = [base + t for t in (plan.get("tasks") or list(task_weights(plan)))]
        missing = missing_tasks(out, tasks)
        fit = os.path.join(out, base, "fit", "parameters.csv")
        if missing or not os.path.exists(fit):
            unfinished += 1
        if missing and os.path.exists(fit):
            sys.stderr.write(f"dem ensemble: {len(missing)} of {len(tasks)} tasks have no result yet, so the fit tables "
                             f"in {os.path.join(out, base, 'fit')} are of a partial ensemble: they are redone when "
                             "every task is finished\n")
            os.unlink(fit)
    summary = os.path.join(out, "sweep", "parameters.csv")
    if sweep and unfinished and os.path.exists(summary):
        sys.stderr.write(f"dem ensemble: {unfinished} of {len(plans)} rows are unfinished, so {out}/sweep is redone "
                         "when they are\n")
        os.unlink(summary)


def drop_stale_groups(out, plans):
    """A packing's group marker (members/mKKK/member.json, rule member) stands for its tasks: when
    one of them has no status file or curve (deleted since), the marker goes, and the group reruns
    just that task (`demkit.task --sequence` skips the others)."""
    for base, plan in plans:
        tasks = plan.get("tasks") or list(task_weights(plan))
        for m in plan["members"]:
            marker = os.path.join(out, base, "members", m["name"], "member.json")
            mine = [base + t for t in tasks if t.startswith(f"members/{m['name']}/")]
            curves = [t[:-len(".json")] + ".csv" for t in mine if "/deviatoric/" in t]   # a mode's result
            if os.path.exists(marker) and missing_tasks(out, mine + curves):
                os.unlink(marker)
                sys.stderr.write(f"dem ensemble: {base}members/{m['name']}: results deleted since it finished: "
                                 "those tasks run again\n")
                # Snakemake does not look below a target that exists: the reduce (and a sweep's
                # summary) must go too, so that the group and then they run again
                for f in (os.path.join(out, base, "fit", "parameters.csv"), os.path.join(out, "sweep", "parameters.csv")):
                    if os.path.exists(f):
                        os.unlink(f)


def missing_tasks(out, tasks):
    return [t for t in tasks if not os.path.exists(os.path.join(out, t))]


def check_slurm():
    """--profile slurm: a controller must answer before any job is submitted."""
    if shutil.which("sbatch") is None or shutil.which("sinfo") is None:
        sys.exit("dem ensemble: --profile slurm, but Slurm's commands (sbatch, sinfo) are not installed: install "
                 "slurm-client (scripts/install-deps.sh), or run without --profile slurm (this machine's cores)")
    try:
        r = subprocess.run(["sinfo", "-h", "-o", "%P"], capture_output=True, text=True, timeout=10)
        ok, why = r.returncode == 0, (r.stderr or r.stdout).strip()
    except subprocess.TimeoutExpired:
        ok, why = False, "sinfo did not answer within 10 s"
    if not ok:
        sys.exit(f"dem ensemble: --profile slurm, but no Slurm controller answers ({why.splitlines()[-1] if why else 'sinfo failed'}): "
                 "start the cluster's slurmctld or point SLURM_CONF at a running one (a throwaway one: "
                 "bash scripts/slurm-local.sh start /tmp/slurm), or run without --profile slurm; nothing was submitted")


def read_status(path):
    try:
        with open(path) as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return None


def free_bytes(path):
    try:
        st = os.statvfs(path)
        return st.f_bavail * st.f_frsize
    except OSError:
        return -1


def explain_failure(out, plans, log_path, code, profile):
    """The cause of a failed workflow, and its fix, with the README's exit code."""
    try:
        with open(log_path, errors="replace") as fh:
            tail = fh.readlines()[-25:]
    except OSError:
        tail = []
    text = "".join(tail)
    preps = {base + m["name"]: read_status(os.path.join(out, base, "members", m["name"], "prep.json"))
             for base, plan in plans for m in plan["members"]}
    blown = {k: v for k, v in preps.items() if v and v.get("status") == "blew_up"}
    free = free_bytes(out)
    if preps and len(blown) == len(preps):
        first = next(iter(blown.values())).get("message", "")
        sys.stderr.write(f"dem ensemble: every preparation blew up ({len(blown)} of {len(preps)} members; "
                         f"{next(iter(blown))}: {first}): no packing to shear. The scene is unstable, and a rerun "
                         "fails the same way: fix it (e.g. a smaller integration.dt_over_tc or slower rates; "
                         "`dem run SCENE --out DIR --set ensemble.packings=1` shows it on one packing), then run "
                         "`dem ensemble` with --force\n")
        return 3
    if (0 <= free < 1 << 20) or "No space left" in text or "disk full" in text:
        sys.stderr.write(f"dem ensemble: the disk holding {out} is full ({max(free, 0)} bytes free): tasks could not "
                         "write their results (only *.part files are left). Free space, then run the same command "
                         "again to continue (finished tasks are kept)\n")
        return 1
    if profile and ("sbatch" in text or "slurm" in text.lower()) and ("rror" in text or "failed" in text):
        line = next((ln.strip() for ln in reversed(tail) if "sbatch" in ln or "slurm" in ln.lower()), "")
        sys.stderr.write(f"dem ensemble: Slurm refused or lost the jobs ({line}): check the cluster (`sinfo`, "
                         "`squeue`; is slurmctld running, is SLURM_CONF right?), then run the same command again to "
                         "continue, or run without --profile slurm\n")
        return 1
    sys.stderr.write(f"dem ensemble: Snakemake failed (exit {code}); the end of {log_path}:\n")
    sys.stderr.write("".join("    " + ln for ln in tail))
    sys.stderr.write("dem ensemble: finished tasks are kept; run the same command again to continue\n")
    return 1


def report_members(out, base=""):
    bad = []
    for f in sorted(glob.glob(os.path.join(out, "members", "*", "**", "*.json"), recursive=True)):
        if os.path.basename(f) == "manifest.json":
            continue
        with open(f) as fh:
            st = json.load(fh)
        if st.get("status") not in (None, "complete"):
            bad.append(f"{base}{os.path.relpath(f, out)}: {st['status']}: {st.get('message') or st.get('reason', '')}")
        elif st.get("warning"):   # e.g. far from quasi-static: said here, not only in logs/
            bad.append(f"{base}{os.path.relpath(f, out)}: {st['warning']}")
    for b in bad:
        sys.stderr.write(f"dem ensemble: warning: {b}\n")


if __name__ == "__main__":
    sys.exit(main())
