"""demkit.breakdown on a hand-built timeline: two cores, three packings (one finished before this
run), one mode each, then the reduce; every part computed by hand below."""
import json
import os

import pytest

from demkit import breakdown

PLAN = {"members": [{"name": "m000"}, {"name": "m001"}, {"name": "m002"}],
        "checkpoints": [{"stem": "unloading_phi0.800"}], "modes": ["D2"]}


def put(root, name, start, end, **extra):
    path = root / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"status": "complete", "t_start": start, "t_end": end, **extra}))


@pytest.fixture
def run(tmp_path):
    put(tmp_path, "members/m002/prep.json", 40.0, 45.0)                  # before this run (t0 = 100): left out
    put(tmp_path, "members/m002/deviatoric/D2_phi0.800.json", 45.0, 50.0)
    put(tmp_path, "members/m000/prep.json", 102.0, 106.0)
    put(tmp_path, "members/m001/prep.json", 103.0, 107.0)
    put(tmp_path, "members/m000/deviatoric/D2_phi0.800.json", 106.5, 110.0)
    put(tmp_path, "members/m001/deviatoric/D2_phi0.800.json", 107.2, 111.0, neighbor_list={"rebuild_s": 1.0})
    put(tmp_path, "logs/reduce.json", 111.5, 114.0, plots_s=1.5)
    return tmp_path


def test_parts_by_hand(run):
    bd = breakdown.breakdown(str(run), [("", PLAN)], 100.0, 115.0, 2, breakdown.reduce_status)
    core_s = {"startup": 2 * 2.0,                        # 100-102, both cores
              "preparations": 4.0 + 4.0,
              "mode tasks": 3.5 + (3.8 - 1.0), "rebuilds": 1.0,
              # a core idle while a task was ready: m001's prep (102-103), m000's mode (106-106.5),
              # m001's mode (107-107.2), the reduce (111-111.5)
              "scheduler": 1.0 + 0.5 + 0.2 + 0.5,
              # a core idle with nothing ready: 110-111 (the reduce waits for m001), 111-111.5 (second
              # core), 111.5-114 (second core beside the reduce)
              "waiting": 1.0 + 0.5 + 2.5,
              "reduction": 2.5 - 1.5, "plots": 1.5,
              "finish": 2 * 1.0}                          # 114-115
    assert sum(core_s.values()) == pytest.approx(2 * 15.0)
    for k, v in core_s.items():
        assert bd["parts_s"][k] == pytest.approx(v / 2, abs=1e-9), k
    assert bd["tasks_run"] == 5 and bd["cores"] == 2 and bd["wall_s"] == 15.0
    assert bd["scheduler_per_task_s"] == pytest.approx(2.2 / 5, abs=1e-3)
    line = breakdown.summary_line(bd)
    assert "where the 15.0 s went" in line and "scheduler 1.1 s (7 %)" in line


def test_more_tasks_at_once_than_cores_widen_the_machine(run):
    """A cluster runs more tasks at once than --cores says: the breakdown counts the cores it saw."""
    put(run, "members/m000/deviatoric/D2_phi0.800.json", 102.0, 110.0)   # three at once from 103
    bd = breakdown.breakdown(str(run), [("", PLAN)], 100.0, 115.0, 1, breakdown.reduce_status)
    assert bd["cores"] == 3
    assert sum(bd["parts_s"].values()) == pytest.approx(15.0)


def test_process_start_time_is_before_now():
    import time
    t = breakdown.process_start_time()
    assert t is not None and time.time() - 600 < t <= time.time()
    assert os.path.exists("/proc/self/stat")


@pytest.mark.parametrize("grouped", [True, False])
def test_a_grouped_packing_runs_in_sequence(tmp_path, grouped):
    """In a group (rule member) a task is ready when the one before it ends: the second core idle
    beside the sequence is waiting, not scheduler overhead; as single tasks, D3 was ready at 2."""
    plan = {"members": [{"name": "m000"}], "checkpoints": [{"stem": "unloading_phi0.800"}], "modes": ["D2", "D3"]}
    put(tmp_path, "members/m000/prep.json", 0.0, 2.0)
    put(tmp_path, "members/m000/deviatoric/D2_phi0.800.json", 2.0, 4.0)
    put(tmp_path, "members/m000/deviatoric/D3_phi0.800.json", 4.0, 6.0)
    put(tmp_path, "logs/reduce.json", 6.0, 7.0)
    if grouped:
        put(tmp_path, "members/m000/member.json", 0.0, 0.0)
    bd = breakdown.breakdown(str(tmp_path), [("", plan)], 0.0, 7.0, 2, breakdown.reduce_status)
    assert bd["parts_s"]["scheduler"] == pytest.approx(0.0 if grouped else 2.0 / 2)
    assert bd["parts_s"]["waiting"] == pytest.approx(7.0 / 2 if grouped else 5.0 / 2)


def test_a_sequence_skips_finished_tasks_and_reruns_a_lost_output(tmp_path):
    """demkit.task --sequence (rule member): a task with its status file and its --out is not run
    again; one whose output was deleted runs again; the group's marker comes when all completed."""
    import subprocess
    import sys
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    count = tmp_path / "count"

    def seg(name, out):
        return ["--status", str(tmp_path / f"{name}.json"), "--log", str(tmp_path / f"{name}.log"), "--",
                "sh", "-c", f"echo x >> {count}; echo {name} > {out}", "--out", str(out)]

    cmd = [sys.executable, "-m", "demkit.task", "--sequence", str(tmp_path / "done.json"), ":::"] + \
        seg("a", a) + [":::"] + seg("b", b)
    env = {**os.environ, "PYTHONPATH": root}
    assert subprocess.run(cmd, env=env).returncode == 0
    assert count.read_text().count("x") == 2 and json.loads((tmp_path / "done.json").read_text())["status"] == "complete"
    assert subprocess.run(cmd, env=env).returncode == 0
    assert count.read_text().count("x") == 2          # both finished: nothing ran
    b.unlink()
    assert subprocess.run(cmd, env=env).returncode == 0
    assert count.read_text().count("x") == 3 and b.read_text() == "b\n"
