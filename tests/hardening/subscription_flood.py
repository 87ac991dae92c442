#!/usr/bin/env python3
"""A hostile client against a real sandtable-coordinator's event socket, by hand (the CTest
cases are coordinator_dos_flood_test's): starts the program, streams subscriptions from
CONNECTIONS raw ZMTP connections (they announce themselves as DEALER, the type the event socket
lets in) for SECONDS, samples the coordinator's VmRSS, then sends SIGTERM and times the exit.

    tests/hardening/subscription_flood.py BUILD_DIR [--connections 4] [--topic-bytes 1000]
        [--seconds 20]

Prints the peak VmRSS, the messages the socket took, the exit status and how long SIGTERM took.
"""
import argparse
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import threading
import time


def find(build, name):
    for root, _, files in os.walk(build):
        if name in files and os.access(os.path.join(root, name), os.X_OK):
            return os.path.join(root, name)
    sys.exit(f"subscription_flood: {name} not found under {build}")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def zmtp_connect(port):
    s = socket.create_connection(("127.0.0.1", port))
    greeting = bytearray(64)
    greeting[0], greeting[9], greeting[10] = 0xFF, 0x7F, 3
    greeting[12:16] = b"NULL"
    ready = b"\x05READY" + b"\x0bSocket-Type" + b"\0\0\0\x06DEALER"
    s.sendall(bytes(greeting) + b"\x04" + bytes([len(ready)]) + ready)
    return s


def frame(body):
    if len(body) < 256:
        return b"\0" + bytes([len(body)]) + body
    return b"\x02" + struct.pack(">Q", len(body)) + body


def rss_kb(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("build")
    parser.add_argument("--connections", type=int, default=4)
    parser.add_argument("--topic-bytes", type=int, default=1000)
    parser.add_argument("--seconds", type=float, default=20.0)
    args = parser.parse_args()
    events, requests = free_port(), free_port()
    coordinator = subprocess.Popen(
        [find(args.build, "sandtable-coordinator"), "--events", f"tcp://127.0.0.1:{events}",
         "--requests", f"tcp://127.0.0.1:{requests}"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    coordinator.stdout.readline()  # the ready line
    stop_at = time.time() + args.seconds
    sent = [0] * args.connections

    def flood(c):
        rng = random.Random(c)
        s = None
        while time.time() < stop_at:
            try:
                if s is None:
                    s = zmtp_connect(events)
                    s.settimeout(0.5)
                batch = b"".join(frame(b"\x01" + rng.randbytes(args.topic_bytes))
                                 for _ in range(64))
                s.sendall(batch)
                sent[c] += 64
            except OSError:
                if s is not None:
                    s.close()
                s = None
                time.sleep(0.01)

    threads = [threading.Thread(target=flood, args=(c,)) for c in range(args.connections)]
    for t in threads:
        t.start()
    peak = 0
    while time.time() < stop_at and coordinator.poll() is None:
        peak = max(peak, rss_kb(coordinator.pid))
        time.sleep(0.5)
    exited_early = coordinator.poll()
    start = time.time()
    if exited_early is None:
        coordinator.send_signal(signal.SIGTERM)
        try:
            coordinator.wait(timeout=15)
        except subprocess.TimeoutExpired:
            coordinator.kill()
            coordinator.wait()
    took = time.time() - start
    for t in threads:
        t.join()
    print(f"{args.connections} connections x {args.topic_bytes}-byte subscriptions for "
          f"{args.seconds:g} s: {sum(sent)} messages taken; peak VmRSS {peak} kB; "
          + (f"exited by itself with {exited_early}" if exited_early is not None else
             f"exit {coordinator.returncode} {took:.3f} s after SIGTERM"))
    return 0 if exited_early is None and coordinator.returncode == 0 and took < 1.0 else 1


if __name__ == "__main__":
    sys.exit(main())
