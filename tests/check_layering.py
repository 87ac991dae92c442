#!/usr/bin/env python3
"""Checks that #include directives respect Sandtable's layers (docs/architecture.md).

Layers point one way: common <- proto <- net <- cluster <- {node, coordinator, sim}. The programs do not
include each other. Inside common/: base <- geometry <- camera <- the rest (estimation,
structured_light, scene, ...). Exits 1 and names every offending line otherwise.
Usage: check_layering.py PROJECT_ROOT
"""
import pathlib
import re
import sys

PROGRAMS = {"node", "coordinator", "sim"}
COMMON_ORDER = {"base": 0, "geometry": 1, "camera": 2}  # others in common/ rank 3


def layer_of(rel_parts):
    top = rel_parts[0]
    if top == "common":
        sub = rel_parts[1] if len(rel_parts) > 1 else ""
        return ("common", COMMON_ORDER.get(sub, 3))
    if top == "proto":
        return ("proto", 10)
    if top == "net":
        return ("net", 11)
    if top == "cluster":
        return ("cluster", 12)
    if top in PROGRAMS:
        return (top, 20)
    return None


def allowed(src, dst):
    (src_top, src_rank), (dst_top, dst_rank) = src, dst
    if dst_rank > src_rank:
        return False
    if dst_rank == 20 and src_top != dst_top:
        return False  # programs never include each other
    return True


def main():
    root = pathlib.Path(sys.argv[1]).resolve()
    include = re.compile(r'^\s*#\s*include\s+"([^"]+)"')
    bad = []
    checked = 0
    for top in ["common", "proto", "net", "cluster", *sorted(PROGRAMS)]:
        for path in sorted((root / top).rglob("*")):
            if path.suffix not in {".h", ".cc", ".hpp", ".cpp"}:
                continue
            rel = path.relative_to(root).parts
            src = layer_of(rel)
            for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
                m = include.match(line)
                if not m:
                    continue
                target = m.group(1)
                parts = target.split("/")
                # Generated protobuf headers live in the build tree as proto/<name>.pb.h.
                dst = layer_of(parts) if parts[0] in {"common", "proto", "net", "cluster", *PROGRAMS} else None
                if dst is None:
                    continue
                checked += 1
                if not allowed(src, dst):
                    bad.append(f"{'/'.join(rel)}:{number}: includes \"{target}\" "
                               f"({dst[0]}) from layer {src[0]}")
    if bad:
        print("layering violations (see docs/architecture.md):")
        print("\n".join(bad))
        return 1
    print(f"layering: {checked} project includes checked, all point down the layers")
    return 0


if __name__ == "__main__":
    sys.exit(main())
