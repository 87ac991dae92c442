#!/usr/bin/env python3
"""A stand-in for a shared library that a packed program loads but never uses: the symbols the
CONSUMERS import from PROVIDER (names, versions, object sizes), each function returning 0 (a
null pointer, false, no error code), written as OUT_DIR/<PROVIDER's soname>.

  tests/bench/device_stub_library.py OUT_DIR PROVIDER_PATH CONSUMER_PATH...

tests/bench/device_render.sh uses it to leave out what OpenCV's image and video modules link
(GDAL, GDCM, FFmpeg, GStreamer, ~230 MB with what they pull) from the programs it carries to a
lent GPU machine: the site's programs read and write PNG only, and open no video."""
import os, re, subprocess, sys

def dyn(path):
    out = subprocess.run(["objdump", "-T", path], capture_output=True, text=True).stdout
    rows = []
    for line in out.splitlines():
        m = re.match(r"^[0-9a-f]+ (.{7}) (\S+)\s+([0-9a-f]+)\s+(?:(\(?[A-Za-z0-9_.]+\)?)\s+)?(\S+)$", line)
        if not m:
            continue
        flags, section, size, version, name = m.groups()
        version = (version or "").strip("()")
        if version == "Base":
            version = ""
        rows.append((flags, section, int(size, 16), version, name))
    return rows

out_dir, provider, consumers = sys.argv[1], sys.argv[2], sys.argv[3:]
soname = subprocess.run(["objdump", "-p", provider], capture_output=True, text=True).stdout
soname = re.search(r"SONAME\s+(\S+)", soname).group(1)
defined = {}
for flags, section, size, version, name in dyn(provider):
    if section != "*UND*":
        defined[(name, version)] = ("O" in flags, size)
wanted = set()
for c in consumers:
    for flags, section, size, version, name in dyn(c):
        if section == "*UND*" and (name, version) in defined:
            wanted.add((name, version))
versions = sorted({v for _, v in wanted if v})
asm = [".text"]
for i, (name, version) in enumerate(sorted(wanted)):
    is_object, size = defined[(name, version)]
    label = f"stub_{i}" if version else name
    if is_object:
        asm += [".data", f".globl {label}", f".type {label},@object", f".size {label},{max(size,1)}",
                f"{label}:", f".zero {max(size,1)}", ".text"]
    else:
        asm += [f".globl {label}", f".type {label},@function", f"{label}:", "xor %eax,%eax", "ret"]
    if version:
        asm.append(f".symver {label},{name}@@{version}")
os.makedirs(out_dir, exist_ok=True)
base = os.path.join(out_dir, soname)
open(base + ".s", "w").write("\n".join(asm) + "\n")
script = "".join(f"{v} {{ }};\n" for v in versions)
if versions:
    script = script.rstrip("\n")
    script = "".join(f"{v} {{ }};\n" for v in versions[:-1]) + f"{versions[-1]} {{ global: *; }};\n"
else:
    script = "{ global: *; };\n"
open(base + ".map", "w").write(script)
subprocess.run(["gcc", "-shared", "-nostdlib", f"-Wl,-soname,{soname}", f"-Wl,--version-script={base}.map",
                base + ".s", "-o", base], check=True)
os.remove(base + ".s"); os.remove(base + ".map")
print(f"{soname}: {len(wanted)} symbols stubbed, {len(versions)} versions")
