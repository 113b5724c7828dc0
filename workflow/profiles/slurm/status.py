#!/usr/bin/env python3
"""Job status for Snakemake's generic cluster mode: prints running, success or failed.

Without it Snakemake 7 waits forever for a job that Slurm killed (time or memory limit). sacct
needs Slurm's accounting database, which small clusters often lack, so `scontrol show job` is
asked first and sacct second. Slurm forgets finished jobs after MinJobAge (300 s by default):
a job neither knows is reported as success, and Snakemake then checks that its outputs exist
(a task without its outputs still fails).
"""
import re
import subprocess
import sys

RUNNING = {"PENDING", "CONFIGURING", "RUNNING", "COMPLETING", "SUSPENDED", "REQUEUED", "RESIZING", "SIGNALING", "STAGE_OUT"}


def state_from_scontrol(job):
    r = subprocess.run(["scontrol", "show", "job", job], capture_output=True, text=True)
    m = re.search(r"JobState=(\S+)", r.stdout) if r.returncode == 0 else None
    return m.group(1) if m else None


def state_from_sacct(job):
    r = subprocess.run(["sacct", "-j", job, "-X", "-n", "-P", "-o", "State"], capture_output=True, text=True)
    lines = [ln.strip() for ln in r.stdout.splitlines() if ln.strip()] if r.returncode == 0 else []
    return lines[0].split()[0] if lines else None


def main():
    job = sys.argv[1].split(";")[0]
    state = state_from_scontrol(job) or state_from_sacct(job)
    if state is None or state == "COMPLETED":
        print("success")
    elif state in RUNNING:
        print("running")
    else:   # FAILED, TIMEOUT, CANCELLED, OUT_OF_MEMORY, NODE_FAIL, PREEMPTED, BOOT_FAIL, DEADLINE
        print("failed")


if __name__ == "__main__":
    main()
