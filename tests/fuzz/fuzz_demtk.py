#!/usr/bin/env python3
"""Fuzzes demtk's entry points: whatever a Python user passes, the interpreter must survive.

    PYTHONPATH=build/python /usr/bin/python3 tests/fuzz/fuzz_demtk.py --seconds 600 [--seed 1]

A Python exception (SceneError, ValueError, RuntimeError, TypeError, BlowUp, ...) is a fine answer;
a crash, an abort or a hang of the interpreter is a finding. libFuzzer cannot drive a Python
module (and atheris is not in Debian), so this is a plain mutation fuzzer: a worker process runs
one input after another, each drawn from a numbered random stream and written to
`last_input.json` before the call; when the worker dies by a signal or stops making progress for
`--hang` seconds, the parent saves that input to tests/fuzz/findings/demtk/ and starts a new
worker after it. The doors (`DOORS`): Scene.from_toml / load_scene (text, dict, overrides),
read_checkpoint, read_packing, State.from_arrays, set_positions / set_velocities and a few
Engine steps, velocity_gradient, fit_saturating and the formatters. Seeds: the repository's
scenes, tests/fuzz/seeds/scene/, a small checkpoint written here and a packing head.
"""
import argparse
import glob
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TOKENS = ["[particles]", "[contact]", "[integration]", "[protocol]", "[output]", "[paths]", "[modes]", "[sweep]",
          "[[contact]]", "count = ", "friction = ", "normal = \"hertz\"", "tangential = \"mindlin\"", "= nan",
          "= inf", "= -1", "= 0", "= 1e308", "= 1e-308", "= \"\"", "= []", "= [[]]", "= {}", "= true", "\"",
          "'", "=", ".", "\n", "#", "\x00", "\xff", "%%", " ", "[", "]", "{", "}", "9" * 30]
NUMBERS = [0.0, -0.0, 1.0, -1.0, 1e308, -1e308, 1e-308, 5e-324, math.nan, math.inf, -math.inf, 2**31, -2**31,
           2**63, 1e-3, 0.5, 3]


def seeds():
    texts = []
    for p in sorted(glob.glob(os.path.join(ROOT, "data", "scenes", "*.toml")) +
                    glob.glob(os.path.join(ROOT, "tests", "fuzz", "seeds", "scene", "*"))):
        with open(p, errors="replace") as f:
            texts.append(f.read())
    packing = ""
    pk = os.path.join(ROOT, "data", "packings", "n9261_phi0.70.txt")
    if os.path.exists(pk):
        with open(pk) as f:
            packing = f.read(3000)
    return texts, packing


def mutate_text(rng, text):
    s = text
    for _ in range(rng.randint(1, 6)):
        op = rng.randrange(6)
        at = rng.randint(0, len(s)) if s else 0
        if op == 0 and s:
            s = s[:at] + s[at + rng.randint(1, 40):]
        elif op == 1:
            s = s[:at] + rng.choice(TOKENS) + s[at:]
        elif op == 2 and s:
            s = s[:at] + chr(rng.randrange(256)) + s[at + 1:]
        elif op == 3 and s:
            b = rng.randint(0, len(s))
            s = s[:at] + s[min(at, b):max(at, b)] + s[at:]
        elif op == 4:
            s = s[:at] + repr(rng.choice(NUMBERS)) + s[at:]
        else:
            s = s[:at]
    return s


def random_override(rng, texts):
    keys = ["contact.friction", "contact.normal", "contact.tangential", "particles.count", "integration.dt_tc",
            "integration.threads", "protocol.modes", "output.vtk", "contact.damping_kg_s", "particles.seed",
            " contact.friction", "contact . friction", "\"contact.friction\"", "x", "", "contact.", ".friction"]
    vals = ["0.5", "nan", "inf", "-1", "1e308", "\"hertz\"", "[1,2]", "", "=", "true", "\"\"", "{}", "x"]
    return rng.choice(keys) + rng.choice(["=", "", "==", " = "]) + rng.choice(vals)


def random_array(rng, n):
    import numpy as np
    shape = rng.choice([(n, 3), (n, 3), (n,), (n + 1, 3), (0, 3), (n, 4), (3, n)])
    a = np.array([rng.choice(NUMBERS) if rng.random() < 0.1 else rng.uniform(-1e-2, 2e-2)
                  for _ in range(int(np.prod(shape)))], dtype=rng.choice(["float64", "float64", "float32", "int64"]))
    return a.reshape(shape)


def door_scene(rng, demtk, texts, tmp):
    text = mutate_text(rng, rng.choice(texts))
    ov = [random_override(rng, texts) for _ in range(rng.randint(0, 3))]
    how = rng.randrange(3)
    if how == 0:
        demtk.Scene.from_toml(text, set=ov)
    elif how == 1:
        p = os.path.join(tmp, "s.toml")
        with open(p, "w", errors="replace") as f:
            f.write(text)
        demtk.load_scene(p, set=ov)
    else:
        d = {rng.choice(["particles", "contact", "x", ""]): {rng.choice(["count", "friction", "a.b", ""]):
             rng.choice(NUMBERS + ["s", [], {}, [1, "a"], True])}}
        demtk.load_scene(d, set=dict(zip(["contact.friction"], [rng.choice(NUMBERS)])))
    return {"door": "scene", "text": text, "overrides": ov, "how": how}


def door_files(rng, demtk, ckpt, packing, tmp):
    p = os.path.join(tmp, "f.bin")
    if rng.random() < 0.5 and ckpt:
        data = bytearray(ckpt)
        for _ in range(rng.randint(1, 8)):
            if data:
                data[rng.randrange(len(data))] = rng.randrange(256)
        if rng.random() < 0.3:
            data = data[:rng.randint(0, len(data))]
        with open(p, "wb") as f:
            f.write(bytes(data))
        demtk.read_checkpoint(p)
        return {"door": "checkpoint", "bytes_hex": bytes(data).hex()}
    text = mutate_text(rng, packing)
    with open(p, "w", errors="replace") as f:
        f.write(text)
    demtk.read_packing(p, rng.choice(NUMBERS + [2000.0]))
    return {"door": "packing", "text": text}


def door_engine(rng, demtk, scene):
    import numpy as np
    state = demtk.random_packing(scene, rng.choice([0.3, 0.5, 0.6]))
    n = state.count
    what = rng.randrange(4)
    arr = random_array(rng, n)
    if what == 0:
        state.set_positions(arr)
    elif what == 1:
        state.set_velocities(arr)
    elif what == 2:
        state = demtk.State.from_arrays(arr, np.abs(random_array(rng, n)).ravel()[:n], [rng.choice(NUMBERS)] * 3,
                                        density=rng.choice(NUMBERS + [2000.0]))
    eng = demtk.Engine(scene, state)
    L = rng.choice([None, [rng.choice(NUMBERS)] * 3, np.eye(3) * rng.choice(NUMBERS), [1, 2], "D2"])
    eng.step(rng.randint(0, 20), velocity_gradient=L, every=rng.choice([0, 1, 5]),
             callback=rng.choice([None, lambda e: e.measure()["s_dev"] > 0]))
    eng.measure(); eng.contacts(); eng.check_sanity()
    scene.velocity_gradient(rng.choice(["D2", "D3", "SS_xz", "", "x", "-D2"]), rng.choice([None] + NUMBERS))
    return {"door": "engine", "what": what, "array": arr.tolist(), "L": repr(L)}


def door_fit(rng, demtk):
    n = rng.randint(0, 12)
    e = [rng.choice(NUMBERS) if rng.random() < 0.1 else i * 0.01 for i in range(n)]
    y = [rng.choice(NUMBERS) if rng.random() < 0.1 else 1 - math.exp(-10 * x) for x in e]
    demtk.fit_saturating(e, y, rng.choice(NUMBERS), rng.choice(NUMBERS))
    demtk.format_paren(rng.choice(NUMBERS), rng.choice(NUMBERS))
    demtk.format_pm(rng.choice(NUMBERS), rng.choice(NUMBERS))
    return {"door": "fit", "e": e, "y": y}


def worker(first, seed, state_dir, count=None):
    import demtk
    texts, packing = seeds()
    tmp = tempfile.mkdtemp(prefix="fuzz_demtk_")
    small = demtk.load_scene(None, set={"particles.count": 60, "integration.threads": 1})
    ckpt_path = os.path.join(state_dir, "seed.ckpt")
    ckpt = open(ckpt_path, "rb").read() if os.path.exists(ckpt_path) else b""
    last = os.path.join(state_dir, "last_input.json")
    i = first
    while count is None or i < first + count:
        rng = random.Random(seed * 1_000_003 + i)
        door = rng.choice(["scene", "scene", "files", "engine", "fit"])
        with open(last, "w") as f:
            json.dump({"index": i, "seed": seed, "door": door}, f)
        try:
            if door == "scene":
                rec = door_scene(rng, demtk, texts, tmp)
            elif door == "files":
                rec = door_files(rng, demtk, ckpt, packing, tmp)
            elif door == "engine":
                rec = door_engine(rng, demtk, small)
            else:
                rec = door_fit(rng, demtk)
        except Exception as e:   # any Python exception is an answer; only a dead interpreter is a finding
            if count is not None:
                print(f"input {i} ({door}): {type(e).__name__}: {e}")
        i += 1
        if i % 20 == 0:
            with open(os.path.join(state_dir, "progress"), "w") as f:
                f.write(str(i))


def make_seed_checkpoint(state_dir):
    import demtk
    scene = demtk.load_scene(None, set={"particles.count": 60, "integration.threads": 1, "contact.friction": 0.5})
    st = demtk.random_packing(scene, 0.5)
    demtk.Engine(scene, st).step(5)
    st.save_checkpoint(os.path.join(state_dir, "seed.ckpt"), scene, "fuzz seed")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--hang", type=float, default=120, help="seconds without progress that count as a hang")
    ap.add_argument("--replay", type=int, default=None, metavar="INDEX",
                    help="run only input INDEX of --seed in this process (to reproduce a finding under gdb)")
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--state", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.replay is not None:
        state = tempfile.mkdtemp(prefix="fuzz_demtk_state_")
        make_seed_checkpoint(state)
        worker(a.replay, a.seed, state, count=1)
        return 0
    if a.worker is not None:
        worker(a.worker, a.seed, a.state)
        return 0
    findings = os.path.join(ROOT, "tests", "fuzz", "findings", "demtk")
    os.makedirs(findings, exist_ok=True)
    state = tempfile.mkdtemp(prefix="fuzz_demtk_state_")
    make_seed_checkpoint(state)
    end, start_index, crashes, starts = time.time() + a.seconds, 0, 0, 0
    progress = os.path.join(state, "progress")
    while time.time() < end:
        starts += 1
        p = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--worker", str(start_index), "--seed",
                              str(a.seed), "--state", state], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        last_seen, last_value = time.time(), None
        while p.poll() is None and time.time() < end:
            time.sleep(0.5)
            v = open(progress).read() if os.path.exists(progress) else None
            if v != last_value:
                last_value, last_seen = v, time.time()
            elif time.time() - last_seen > a.hang:
                p.kill()
                break
        if p.poll() is None:          # the time is up
            p.send_signal(signal.SIGKILL); p.wait()
            hung = time.time() < end
        else:
            hung = False
        rc = p.returncode
        if rc != 0 and (hung or time.time() < end or rc > 0):
            info = json.load(open(os.path.join(state, "last_input.json")))
            crashes += 1
            name = f"{'hang' if hung else 'crash'}-seed{info['seed']}-{info['index']}.json"
            info.update({"returncode": rc, "stderr_tail": p.stderr.read().decode(errors="replace")[-3000:]})
            with open(os.path.join(findings, name), "w") as f:
                json.dump(info, f, indent=1)
            print(f"fuzz_demtk: finding {name} (return code {rc})", flush=True)
            start_index = info["index"] + 1
        else:
            start_index = int(open(progress).read()) if os.path.exists(progress) else start_index
    done = int(open(progress).read()) if os.path.exists(progress) else 0
    print(f"fuzz_demtk: {done} inputs in {a.seconds:.0f} s (seed {a.seed}), {starts} worker starts, {crashes} findings")
    return 1 if crashes else 0


if __name__ == "__main__":
    sys.exit(main())
