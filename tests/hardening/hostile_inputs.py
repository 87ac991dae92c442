#!/usr/bin/env python3
"""Hostile inputs against every program's file flags: each must be refused with exit status 2
and a message naming the file, within a bounded time, never a crash, a hang or a traceback of
std::terminate. Run by ctest (hardening_hostile_inputs) and by hand:

    tests/hardening/hostile_inputs.py BUILD_DIR [--only SUBSTRING] [--table FILE.md]

Kinds of input: a missing path, a directory, a FIFO nobody writes, /dev/zero, an empty file,
random bytes, a JSON array where an object is expected, a JSON document cut in half, a number
of 400 digits. Each program is given one hostile input at a time, the other inputs valid.
"""
import argparse
import os
import random
import subprocess
import sys
import tempfile
import time

TIMEOUT_S = 30.0  # one case: a hang past this is a failure
CRASH_MARKS = ("terminate called", "Aborted", "Segmentation fault", "what():", "AddressSanitizer",
               "core dumped", "Assertion", "std::")


def find(build, name):
    for root, _, files in os.walk(build):
        if name in files and os.access(os.path.join(root, name), os.X_OK):
            return os.path.join(root, name)
    sys.exit(f"hostile_inputs: {name} not found under {build}")


def make_kinds(tmp):
    kinds = {}
    kinds["missing"] = os.path.join(tmp, "does-not-exist.json")
    d = os.path.join(tmp, "a-directory")
    os.makedirs(d, exist_ok=True)
    kinds["directory"] = d
    fifo = os.path.join(tmp, "a-fifo")
    if not os.path.exists(fifo):
        os.mkfifo(fifo)
    kinds["fifo"] = fifo
    kinds["dev-zero"] = "/dev/zero"
    rng = random.Random(10)
    for name, data in (("empty", b""),
                       ("random", bytes(rng.randrange(256) for _ in range(4096))),
                       ("json-array", b"[1, 2, 3]\n"),
                       ("json-cut", b'{"format": "sandtable.site", "version": 1, "units": [{"id": 0, '),
                       ("huge-number", b'{"version": ' + b"9" * 400 + b"}\n")):
        p = os.path.join(tmp, "bad-" + name)
        with open(p, "wb") as f:
            f.write(data)
        kinds[name] = p
    return kinds


def run(cmd, cwd):
    start = time.monotonic()
    try:
        p = subprocess.run(cmd, cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True,
                           timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return None, "", time.monotonic() - start
    return p.returncode, p.stderr.decode(errors="replace") + p.stdout.decode(errors="replace"), \
        time.monotonic() - start


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("build")
    ap.add_argument("--only", default="")
    ap.add_argument("--table", default="")
    args = ap.parse_args()
    build = os.path.abspath(args.build)
    world = find(build, "sandtable-world")
    lab = find(build, "sandtable-lab")
    node = find(build, "sandtable-node")
    coord = find(build, "sandtable-coordinator")
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

    tmp = tempfile.mkdtemp(prefix="sandtable-hostile-")
    kinds = make_kinds(tmp)
    good = os.path.join(tmp, "good")
    os.makedirs(good, exist_ok=True)
    site, scene = os.path.join(good, "site.json"), os.path.join(good, "scene.glb")
    factory = os.path.join(good, "factory")
    for cmd in ([world, "make-scene", "--preset", "sandtable", "-o", scene],
                [world, "make-site", "--preset", "sandtable-3", "--factory-dir", factory, "-o", site]):
        rc, out, _ = run(cmd, root)
        if rc != 0:
            sys.exit(f"hostile_inputs: could not make the valid inputs: {' '.join(cmd)}: {out}")
    factory0 = os.path.join(factory, sorted(os.listdir(factory))[0])
    out_png = os.path.join(tmp, "out.png")
    no_coordinator = "tcp://127.0.0.1:9,tcp://127.0.0.1:9"

    # (case name, argv with {X} for the hostile path)
    cases = [
        ("world render --site", [world, "render", "--site", "{X}", "--scene", scene, "--white",
                                 "--view", "top", "--width", "64", "-o", out_png]),
        ("world render --scene", [world, "render", "--site", site, "--scene", "{X}", "--white",
                                  "--view", "top", "--width", "64", "-o", out_png]),
        ("world render --frame", [world, "render", "--site", site, "--scene", scene,
                                  "--frame", "0={X}", "--view", "top", "--width", "64", "-o", out_png]),
        ("world serve --site", [world, "serve", "--site", "{X}", "--scene", scene]),
        ("world serve --scene", [world, "serve", "--site", site, "--scene", "{X}"]),
        ("lab run --site", [lab, "run", "--site", "{X}", "--out", os.path.join(tmp, "lab")]),
        ("lab run --scene", [lab, "run", "--scene", "{X}", "--out", os.path.join(tmp, "lab")]),
        ("lab run --model", [lab, "run", "--model", "{X}", "--out", os.path.join(tmp, "lab")]),
        ("node --model", [node, "--id", "0", "--coordinator", no_coordinator, "--world",
                          "tcp://127.0.0.1:9", "--factory", factory0, "--model", "{X}"]),
        ("node --factory", [node, "--id", "0", "--coordinator", no_coordinator, "--world",
                            "tcp://127.0.0.1:9", "--factory", "{X}"]),
        ("node --true-pose", [node, "--id", "0", "--coordinator", no_coordinator, "--world",
                              "tcp://127.0.0.1:9", "--factory", factory0, "--true-pose", "{X}"]),
        ("node --curve-keys", [node, "--id", "0", "--coordinator", no_coordinator,
                               "--curve-keys", "{X}"]),
        ("node calibrate-unit --poses", [node, "calibrate-unit", "--poses", "{X}",
                                         "-o", os.path.join(tmp, "unit.json")]),
        ("coordinator --timeline", [coord, "--timeline", "{X}"]),
        ("coordinator --tracker-replay", [coord, "--tracker-replay", "{X}"]),
        ("coordinator --table-from-tracker",
         [coord, "--tracker-replay",
          os.path.join(root, "..", "shared", "data", "polhemus-hand", "README.md"),
          "--table-from-tracker", "{X}"]),
        ("coordinator --virtual-wand", [coord, "--virtual-wand", "{X}"]),
        ("coordinator --scene", [coord, "--scene", "{X}"]),
        ("coordinator --curve-keys", [coord, "--curve-keys", "{X}"]),
        ("coordinator --import-session", [coord, "--annotations", os.path.join(tmp, "a.db"),
                                          "--import-session", "{X}"]),
        ("coordinator --annotations", [coord, "--annotations", "{X}", "--export-session",
                                       os.path.join(tmp, "export.jsonl")]),
    ]
    # The --table-from-tracker case needs a valid recording: use the first .traj in the data.
    data = os.path.join(root, "..", "shared", "data", "polhemus-hand")
    trajs = sorted(f for f in os.listdir(data) if f.endswith((".traj", ".csv"))) if os.path.isdir(data) else []
    if trajs:
        cases = [(n, [trajs and os.path.join(data, trajs[0]) if a.endswith("README.md") else a for a in c])
                 for n, c in cases]
    else:
        cases = [c for c in cases if c[0] != "coordinator --table-from-tracker"]

    failures, rows = [], []
    for name, argv in cases:
        for kind, path in kinds.items():
            label = f"{name} <{kind}>"
            if args.only and args.only not in label:
                continue
            if kind in ("missing", "empty") and name == "coordinator --annotations":
                continue  # an absent or empty database is a new one: a valid start
            cmd = [a.replace("{X}", path) for a in argv]
            rc, out, took = run(cmd, root)
            problem = ""
            if rc is None:
                problem = f"hang (no exit in {TIMEOUT_S:.0f} s)"
            elif rc < 0:
                problem = f"killed by signal {-rc}"
            elif rc != 2:
                problem = f"exit status {rc}, expected 2"
            elif any(m in out for m in CRASH_MARKS):
                problem = "crash marks in output"
            elif os.path.basename(path) not in out:
                problem = "message does not name the file"
            first = next((l for l in out.splitlines() if l.strip()), "")[:160]
            rows.append((label, rc, took, problem or "ok", first))
            if problem:
                failures.append(f"{label}: {problem}: {first}")
    if args.table:
        with open(args.table, "w") as f:
            f.write("| case | exit | s | result | first line |\n|---|---|---|---|---|\n")
            for label, rc, took, res, first in rows:
                f.write(f"| {label} | {rc} | {took:.2f} | {res} | {first.replace('|', '/')} |\n")
    print(f"hostile_inputs: {len(rows)} cases, {len(failures)} failures")
    for f in failures:
        print("  FAIL " + f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
