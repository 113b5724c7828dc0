"""Where the wall time of one `dem ensemble` run went: the breakdown it prints at the end and stores
in DIR/run.json.

Every task's status JSON (demkit.task) holds the start and end (epoch seconds) of its `dem`
command. Over the run's wall time [t0, t1] the machine offers `cores` x (t1 - t0) core-seconds; the
breakdown gives each task's interval to its kind (preparations, mode tasks, their list rebuilds
by the seconds `dem mode` measured, reduction and plots) and classifies the idle core-seconds
instant by instant (a timeline sweep):

  startup     before the first task starts (scene check, `dem info`, Snakemake's DAG)
  scheduler   a core idle while a task whose inputs are done has not started: Snakemake's and the
              task wrapper's per-task cost (the 'scheduler overhead per task' is this over the tasks)
  waiting     a core idle with nothing ready (the reduce waiting for the last mode, the tail)
  finish      after the last task (Snakemake's and the driver's end)

Each part is reported in seconds of wall time (core-seconds / cores), so the parts add up to the
wall time by construction of the sweep; the test checks them against the wall time measured
outside the run and each task kind against its status files. Tasks that finished before this run
(a resumed run) are not in it.
"""
import json
import os
import time

KINDS = ("startup", "preparations", "mode tasks", "rebuilds", "scheduler", "waiting", "reduction", "plots", "finish")


def read_json(path):
    try:
        with open(path) as fh:
            return json.load(fh)
    except (OSError, ValueError):
        return None


def task_list(out, plans, reduce_status):
    """[(name, kind, status, [names of the tasks it needs])] of every planned task."""
    tasks = []
    for base, plan in plans:
        modes = []
        for m in plan["members"]:
            prep = f"{base}members/{m['name']}/prep.json"
            tasks.append((prep, "prep", []))
            # a grouped packing (rule member) runs its tasks in sequence: each needs the one before
            grouped = os.path.exists(os.path.join(out, base, "members", m["name"], "member.json"))
            for c in plan["checkpoints"]:
                phi = c["stem"].rsplit("_", 1)[1]
                for mode in plan["modes"]:
                    name = f"{base}members/{m['name']}/deviatoric/{mode}_{phi}.json"
                    tasks.append((name, "mode", [tasks[-1][0] if grouped else prep]))
                    modes.append(name)
        tasks.append((reduce_status(base), "reduce", modes))
    return [(n, k, read_json(os.path.join(out, n)), deps) for n, k, deps in tasks]


def intervals(tasks, t0, t1):
    """{name: (start, end, status)} of the tasks this run ran (their command started at or after t0);
    `ready`: {name: time its inputs were done} for the tasks that had not finished before t0."""
    ran, done_before = {}, set()
    for name, _, st, _ in tasks:
        if not st or "t_start" not in st:
            if st:
                done_before.add(name)
            continue
        if st["t_start"] >= t0 - 1e-3:
            ran[name] = (st["t_start"], min(st["t_end"], t1), st)
        else:
            done_before.add(name)
    ends = {n: iv[1] for n, iv in ran.items()}
    ready = {}
    for name, _, _, deps in tasks:
        if name in done_before:
            continue
        ready[name] = max([t0] + [ends.get(d, t0) if d in ran or d in done_before else t1 for d in deps])
    return ran, ready


def breakdown(out, plans, t0, t1, cores, reduce_status):
    """The parts of [t0, t1] as a dict (see the module's doc); `plans` as in demkit.ensemble."""
    tasks = task_list(out, plans, reduce_status)
    kind = {n: k for n, k, _, _ in tasks}
    ran, ready = intervals(tasks, t0, t1)
    cores = max([cores] + [overlap(ran, t) for t in sorted({iv[0] for iv in ran.values()})])
    core_s = dict.fromkeys(KINDS, 0.0)
    for name, (a, b, st) in ran.items():
        dt = max(0.0, b - a)
        if kind[name] == "prep":
            core_s["preparations"] += dt
        elif kind[name] == "mode":
            rebuild = min(dt, max(0.0, float((st.get("neighbor_list") or {}).get("rebuild_s", 0.0))))
            core_s["rebuilds"] += rebuild
            core_s["mode tasks"] += dt - rebuild
        else:
            plots = min(dt, float(st.get("plots_s", 0.0)))
            core_s["plots"] += plots
            core_s["reduction"] += dt - plots
    first = min([iv[0] for iv in ran.values()], default=t1)
    last = max([iv[1] for iv in ran.values()], default=t1)
    cuts = sorted({t0, t1, first, last} | {t for iv in ran.values() for t in iv[:2]} |
                  {t for t in ready.values() if t0 <= t <= t1})
    for a, b in zip(cuts[:-1], cuts[1:]):
        if b <= a or a < t0 or b > t1:
            continue
        idle = max(0, cores - overlap(ran, a))
        if a < first:
            core_s["startup"] += idle * (b - a)
        elif a >= last:
            core_s["finish"] += idle * (b - a)
        else:
            waiting_ready = sum(1 for n, r in ready.items() if r <= a and (n not in ran or ran[n][0] > a))
            core_s["scheduler"] += min(idle, waiting_ready) * (b - a)
            core_s["waiting"] += (idle - min(idle, waiting_ready)) * (b - a)
    parts = {k: round(v / cores, 3) for k, v in core_s.items()}
    return {"wall_s": round(t1 - t0, 3), "cores": cores, "tasks_run": len(ran), "parts_s": parts,
            "scheduler_per_task_s": round(core_s["scheduler"] / len(ran), 3) if ran else 0.0,
            "task_core_s": round(sum(max(0.0, b - a) for a, b, _ in ran.values()), 3)}


def overlap(ran, t):
    """Tasks running at time t (start <= t < end)."""
    return sum(1 for a, b, _ in ran.values() if a <= t < b)


def summary_line(bd):
    """One line for the end of `dem ensemble`."""
    wall = bd["wall_s"] or 1.0
    parts = ", ".join(f"{k} {v:.1f} s ({100 * v / wall:.0f} %)" for k, v in bd["parts_s"].items() if v >= 0.05)
    return (f"dem ensemble: where the {bd['wall_s']:.1f} s went ({bd['cores']} cores; core-seconds / cores): {parts}; "
            f"scheduler overhead {bd['scheduler_per_task_s']:.2f} core-s per task over {bd['tasks_run']} tasks")


def process_start_time():
    """Epoch seconds at which this process started (`dem ensemble` execs the driver, so this is the
    start of the command the user typed), or None where /proc is not there."""
    try:
        with open("/proc/self/stat") as fh:
            ticks = int(fh.read().rsplit(")", 1)[1].split()[19])   # starttime: clock ticks after boot
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        return time.time() - (uptime - ticks / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError):
        return None


def reduce_status(base):
    """The reduce's status JSON of the ensemble at `base` (workflow/Snakefile, rule reduce)."""
    return f"{base}logs/reduce.json"


def report(out, plans, t0, cores, stream):
    """Print the breakdown of the run that started at t0 and store it in DIR/run.json."""
    from demkit.atomic import write_json_atomic
    bd = breakdown(out, plans, t0, time.time(), cores, reduce_status)
    stream.write(summary_line(bd) + "\n")
    write_json_atomic(os.path.join(out, "run.json"), {"status": "complete", "breakdown": bd})
    return bd
