"""One workflow task: run a `dem` command, keep its stderr in a log, write a status file.

    python3 -m demkit.task --status S.json --log L.log [--requires P.json] -- dem ARGS...

Exit codes of `dem` (README): 0 done, 3 blow-up. A blow-up is a result of the simulation, not a
failure of the task: the status file says `blew_up` with the runner's message, the reduce step
reports the member and leaves it out of the averages. Any other exit code fails the task (the
workflow stops it and retries it on the next run). `--requires` names the status file of the
task this one builds on: if that one did not complete, this task is skipped with a status
saying why (so a packing whose preparation blew up is reported, not silently dropped).

    python3 -m demkit.task --sequence DONE.json ::: TASK ARGS ::: TASK ARGS ...

runs a group of such tasks (a packing's preparation and its modes: workflow/Snakefile, rule
member) one after the other in this process, so the workflow's per-task cost is paid once per
group; a task whose status file exists is not run again (a killed group resumes like single
tasks), and DONE is written when every task completed.
"""
import argparse
import json
import os
import re
import resource
import subprocess
import sys
import time

from demkit.atomic import write_json_atomic


def last_error_line(log_path):
    try:
        with open(log_path) as fh:
            lines = [ln.strip() for ln in fh if ln.strip()]
    except OSError:
        return ""
    for ln in reversed(lines):
        if ln.startswith("dem"):
            return ln
    return lines[-1] if lines else ""


NEIGHBOR_LIST_LINE = "dem mode: neighbor_list "


def neighbor_list_summary(output):
    """The JSON object of `dem mode`'s last `dem mode: neighbor_list {...}` line (rebuild counts,
    their wall-time share, triggers: rattler, packing, deformation, flip), or None."""
    for ln in reversed(output.splitlines()):
        if ln.startswith(NEIGHBOR_LIST_LINE):
            try:
                return json.loads(ln[len(NEIGHBOR_LIST_LINE):])
            except ValueError:
                return None
    return None


PLOT_LINE = re.compile(r"^dem plot: \d+ figures in .* \(([0-9.]+) s\)$")


def plot_seconds(output):
    """Seconds of the plots, from demkit.ensemble_plots' line `dem plot: N figures in DIR (S s)`, or None."""
    for ln in reversed(output.splitlines()):
        m = PLOT_LINE.match(ln.strip())
        if m:
            return float(m.group(1))
    return None


def parser():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--status", help="status JSON to write (complete | blew_up | skipped)")
    ap.add_argument("--log", required=True, help="file for the command's stderr")
    ap.add_argument("--requires", help="status JSON of the task this one builds on")
    ap.add_argument("command", nargs=argparse.REMAINDER)
    return ap


SEPARATOR = ":::"


def outputs(cmd):
    """What a `dem` command writes (the value of its --out): a task whose status file stands but
    whose curve is gone is not done."""
    return [cmd[i + 1] for i, x in enumerate(cmd[:-1]) if x == "--out"]


def run_sequence(done, segments):
    """The tasks of one group in order, in this process: a task whose status file exists finished
    in an earlier run (status files are written atomically, last) and is not run again, so a group
    killed midway resumes like single tasks. Every task runs even when one fails (the next run
    retries only that one); DONE (the group's own output) is written when all completed."""
    rc, statuses = 0, []
    for seg in segments:
        a = parser().parse_args(seg)
        statuses.append(a.status)
        if a.status and os.path.exists(a.status) and all(os.path.exists(f) for f in outputs(a.command)):
            continue
        if a.requires and not os.path.exists(a.requires):   # the task it builds on failed: retried next run
            rc = rc or 1
            continue
        r = run_task(seg)
        rc = rc or r
    if rc == 0:
        write_json_atomic(done, {"status": "complete", "tasks": statuses})
    return rc


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--sequence"]:   # --sequence DONE.json ::: TASK ARGS ::: TASK ARGS ...
        if len(argv) < 4 or argv[2] != SEPARATOR:
            sys.exit("demkit.task: usage: --sequence DONE.json ::: --status S --log L -- CMD ... [::: ...]")
        segments, cur = [], []
        for x in argv[3:] + [SEPARATOR]:
            if x == SEPARATOR:
                segments.append(cur)
                cur = []
            else:
                cur.append(x)
        return run_sequence(argv[1], [seg for seg in segments if seg])
    return run_task(argv)


def run_task(argv):
    ap = parser()
    a = ap.parse_args(argv)
    cmd = a.command[1:] if a.command and a.command[0] == "--" else a.command
    if not cmd:
        ap.error("no command after --")
    if a.requires:
        with open(a.requires) as fh:
            before = json.load(fh)
        if before.get("status") != "complete":
            write_json_atomic(a.status, {"status": "skipped", "command": cmd,
                                         "reason": f"{a.requires}: {before.get('status')}: {before.get('message', '')}"})
            return 0
    os.makedirs(os.path.dirname(a.log) or ".", exist_ok=True)
    t0 = time.time()
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    # The command's output is kept in memory too: on a full disk the log may stay empty, and the
    # cause must still reach the workflow's log and the driver.
    r = subprocess.run(cmd, stderr=subprocess.STDOUT, stdout=subprocess.PIPE)
    rc = r.returncode
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)   # user + sys of the command: its cost on a busy machine
    output = r.stdout.decode(errors="replace")
    log_error = ""
    try:
        with open(a.log, "w") as log:
            log.write(output)
    except OSError as e:
        log_error = f"; the log could not be written ({e.strerror})"
    wall = time.time() - t0
    if rc not in (0, 3):
        lines = [ln.strip() for ln in output.splitlines() if ln.strip()]
        last = next((ln for ln in reversed(lines) if ln.startswith("dem")), lines[-1] if lines else "")
        sys.stderr.write(f"demkit.task: {' '.join(cmd)} exited {rc}: {last} (log: {a.log}{log_error})\n")
        return rc
    if a.status:
        # t_start/t_end (epoch s) place the command on the run's timeline (demkit.breakdown)
        status = {"status": "complete" if rc == 0 else "blew_up", "exit_code": rc, "wall_s": round(wall, 3),
                  "t_start": round(t0, 3), "t_end": round(t0 + wall, 3), "cpu_s": round(cpu, 3),
                  "command": cmd, "host": os.uname().nodename}
        if rc == 3:
            lines = [ln.strip() for ln in output.splitlines() if ln.strip()]
            status["message"] = next((ln for ln in reversed(lines) if ln.startswith("dem")), lines[-1] if lines else "")
        nl = neighbor_list_summary(output)
        if nl is not None:   # rebuilds, their share of the wall time and what triggered them
            status["neighbor_list"] = nl
        plots = plot_seconds(output)
        if plots is not None:   # the reduce: its plots' share (demkit.ensemble_plots' last line)
            status["plots_s"] = plots
        warnings = [ln.strip() for ln in output.splitlines() if "warning:" in ln][:20]
        if warnings:   # e.g. far from quasi-static: read by the driver and by the fit tables
            status["warning"] = " | ".join(warnings)
        write_json_atomic(a.status, status)
    return 0


if __name__ == "__main__":
    sys.exit(main())
