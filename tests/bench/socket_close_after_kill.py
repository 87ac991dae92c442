#!/usr/bin/env python3
"""How long after a SIGKILL a process's TCP socket closes, against its resident memory.

A child touches N MB, connects to us and waits; we SIGKILL it and time until its socket reads
EOF (the kernel unmaps the memory before it closes the files). Run it plain and with
GLIBC_TUNABLES=glibc.malloc.hugetlb=1 (the child's heap on transparent huge pages), as the lab
starts nodes (docs/results.md, "Re-blend after a neighbour is killed"):

    python3 tests/bench/socket_close_after_kill.py
    GLIBC_TUNABLES=glibc.malloc.hugetlb=1 python3 tests/bench/socket_close_after_kill.py
"""
import os
import signal
import socket
import subprocess
import sys
import time

for mb in (10, 200, 500, 1000, 2000):
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    child_code = (
        "import socket, time\n"
        f"b = bytearray({mb} * 1024 * 1024)\n"
        "for i in range(0, len(b), 4096): b[i] = 1\n"
        f"s = socket.create_connection(('127.0.0.1', {port}))\n"
        "s.sendall(b'r')\n"
        "time.sleep(100)\n")
    child = subprocess.Popen([sys.executable, "-c", child_code], env=dict(os.environ))
    conn, _ = server.accept()
    conn.recv(1)
    start = time.monotonic()
    os.kill(child.pid, signal.SIGKILL)
    conn.recv(1)  # EOF once the killed process's sockets are closed
    print(f"{mb} MB: socket closed {1000 * (time.monotonic() - start):.2f} ms after SIGKILL")
    child.wait()
    conn.close()
    server.close()
