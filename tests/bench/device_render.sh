#!/usr/bin/env bash
# The renderer on a real GPU with no display: the frame-time benchmark at three sizes, the
# renderer's golden-image and projection tests, and the lab on sandtable-3 (the default run and a
# kill), on a machine lent with an NVIDIA GPU (the workplace's device tool; it has none of our
# Debian libraries, and takes 64 MiB per call).
#
#   tests/bench/device_render.sh pack [BUILD_DIR]  # here: the programs + the shared libraries
#                                                  # they need, stripped, as .gpubench/pack.tar.xz
#                                                  # (git-ignored; ~50 MB, 2-3 min on 2 cores)
#   tests/bench/device_render.sh run OUT_DIR       # there, from the repository root, after the
#                                                  # glvnd loaders (.gl/*.deb) are unpacked into /
#   FRAMES=600 (per benchmark run), STAGES="bench tests lab" (any of them)
#
# GL itself is not packed: glvnd's libEGL/libOpenGL dispatch to the machine's NVIDIA driver,
# reached through EGL_EXT_platform_device (node/render/gl_context.cc). docs/results.md has the
# figures and the exact call.
set -uo pipefail
mode="${1:-}"
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
pack="$root/.gpubench"
unpacked=/tmp/gpubench

if [ "$mode" = pack ]; then
  build="${2:-$root/build}"
  staging="$(mktemp -d)/gpubench"
  mkdir -p "$staging/bin" "$staging/lib" "$staging/lib-cxx" "$pack"
  programs=(tests/bench/sandtable_render_bench tests/node/render/node_render_renderer_test
            tests/node/render/node_render_show_content_test sim/lab/sandtable-lab
            sim/app/sandtable-world node/sandtable-node coordinator/sandtable-coordinator)
  for p in "${programs[@]}"; do
    [ -x "$build/$p" ] || { echo "device_render: no $build/$p: build it first" >&2; exit 2; }
    strip -o "$staging/bin/$(basename "$p")" "$build/$p"
  done
  # Stand-ins for what OpenCV's image codecs (GDAL, GDCM) and video module (FFmpeg, GStreamer,
  # gphoto2, dc1394) link: loaded, never used (device_stub_library.py).
  system=/lib/x86_64-linux-gnu
  for p in libgdal.so.32 libgdcmMSFF.so.3.0 libgdcmDSED.so.3.0; do
    python3 "$root/tests/bench/device_stub_library.py" "$staging/lib" "$system/$p" \
      "$system/libopencv_imgcodecs.so.406" || exit 2
  done
  videoio="$system/libopencv_videoio.so.406"
  for p in $(readelf -d "$videoio" | sed -n 's/.*NEEDED.*\[\(.*\)\]/\1/p' |
    grep -v -E '^(libopencv_|libm\.|libstdc|libgcc_s|libc\.)'); do
    python3 "$root/tests/bench/device_stub_library.py" "$staging/lib" "$system/$p" "$videoio" ||
      exit 2
  done
  # Every other shared library the programs load, but the C library, the C++ runtime (packed
  # apart, used only where the machine's is older) and GL (the machine's driver through glvnd).
  LD_LIBRARY_PATH="$staging/lib" ldd "$staging"/bin/* | grep -v "$staging/lib" | awk '/=> \//{print $3}' | sort -u | while read -r lib; do
    case "$(basename "$lib")" in
      libc.so.*|libm.so.*|libpthread.so.*|libdl.so.*|librt.so.*|ld-linux*|libresolv.so.*) ;;
      libEGL*|libGL*|libOpenGL*|libGLX*|libGLdispatch*|libgbm*|libdrm*|libvulkan*) ;;
      libstdc++*|libgcc_s*) cp -L "$lib" "$staging/lib-cxx/" ;;
      *) cp -L "$lib" "$staging/lib/" ;;
    esac
  done
  strip --strip-unneeded "$staging"/lib/* 2> /dev/null
  if LD_LIBRARY_PATH="$staging/lib:$staging/lib-cxx" ldd "$staging"/bin/* | grep "not found"; then
    echo "device_render: a library is missing from the pack" >&2
    exit 2
  fi
  tar -C "$(dirname "$staging")" -cf - gpubench | xz -T0 -9 > "$pack/pack.tar.xz"
  rm -rf "$(dirname "$staging")"
  ls -l "$pack/pack.tar.xz"
  exit 0
fi

if [ "$mode" != run ] || [ -z "${2:-}" ]; then
  sed -n '2,13p' "$0" >&2
  exit 2
fi
out="$2"
mkdir -p "$out"
cd "$root" || exit 2
rm -rf "$unpacked" && tar -C "$(dirname "$unpacked")" -xJf "$pack/pack.tar.xz" || exit 2
export LD_LIBRARY_PATH="$unpacked/lib"
cxx="$(ldconfig -p | awk '/libstdc\+\+\.so\.6 .*x86-64/{print $NF; exit}')"
if [ -z "$cxx" ] || ! grep -qa GLIBCXX_3.4.30 "$cxx"; then
  LD_LIBRARY_PATH="$LD_LIBRARY_PATH:$unpacked/lib-cxx"
fi
vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
[ -f "$vendor" ] && export __EGL_VENDOR_LIBRARY_FILENAMES="$vendor"
nvidia-smi --query-gpu=name,driver_version,clocks.sm,clocks.max.sm --format=csv 2>&1 |
  tee "$out/summary.txt"
nproc | sed 's/^/cpus: /' | tee -a "$out/summary.txt"

stages="${STAGES:-bench tests lab}"
bench="$unpacked/bin/sandtable_render_bench"
[[ " $stages " == *" bench "* ]] && for size in 1280x800 1920x1200 3840x2160; do
  w="${size%x*}" h="${size#*x}"
  echo "== render bench $size"
  timeout 120 "$bench" --frames "${FRAMES:-600}" --width "$w" --height "$h" \
    --out "$out/render-bench-$size.json" > /tmp/render-bench.log 2>&1
  rc=$?
  echo "rc=$rc"
  [ "$rc" = 0 ] || tail -n 20 /tmp/render-bench.log
done
summarise() {
  python3 - "$@" << 'PY'
import json, sys
for path in sys.argv[1:]:
    try:
        d = json.load(open(path))
    except Exception as e:
        print(path, "unreadable:", e)
        continue
    print(d["context"])
    print(f'{d["width_px"]}x{d["height_px"]}: frame p50 {d["frame_ms_p50"]:.3f} p99 '
          f'{d["frame_ms_p99"]:.3f} ms, floor p50 {d["floor_ms_p50"]:.3f} ms, '
          f'x{d["frame_over_floor"]:.2f}, set_mask {d["set_mask_ms_p50"]:.3f}, '
          f'read_output {d["read_output_ms_p50"]:.3f} ms')
    for k in ("deferred", "separate_warp_pass", "folded"):
        v = d[k]
        passes = " ".join(f"{p}={t:.3f}" for p, t in v.get("pass_ms_p50", {}).items())
        print(f'  {k}: p50 {v["frame_ms_p50"]:.3f} p99 {v["frame_ms_p99"]:.3f} '
              f'rewarp {v.get("rewarp_ms_p50", 0):.3f} prepared first/p50/max '
              f'{v.get("prepared_rewarp_ms_first", 0):.3f}/{v.get("prepared_rewarp_ms_p50", 0):.3f}/'
              f'{v.get("prepared_rewarp_ms_max", 0):.3f} | {passes}')
PY
}
[[ " $stages " == *" bench "* ]] && summarise "$out"/render-bench-*.json | tee -a "$out/summary.txt"

[[ " $stages " == *" tests "* ]] && for t in node_render_renderer_test node_render_show_content_test; do
  timeout 180 "$unpacked/bin/$t" >> "$out/render-tests.txt" 2>&1
  echo "$t rc=$?" | tee -a "$out/render-tests.txt"
done
[[ " $stages " == *" tests "* ]] &&
  grep -E "^\[  (FAILED|PASSED) |Failure|off by" "$out/render-tests.txt" | head -n 40

# The lab on sandtable-3: the default run (calibration, blend, show), then a neighbour killed.
lab() {
  local name="$1"
  shift
  echo "== lab $name: $*" | tee -a "$out/lab.log"
  timeout 240 "$unpacked/bin/sandtable-lab" run --bin-dir "$unpacked/bin" --out "/tmp/$name" "$@" \
    >> "$out/lab.log" 2>&1
  echo "lab $name rc=$?" | tee -a "$out/lab.log"
  cp "/tmp/$name/report.json" "$out/$name-report.json" 2> /dev/null || return 0
  python3 - "$out/$name-report.json" << 'PY' | tee -a "$out/summary.txt"
import json, sys
d = json.load(open(sys.argv[1]))
print(sys.argv[1].split("/")[-1], "status", d.get("status"), "total_s", d.get("total_s"))
r = d.get("render", {})
print("  render:", {k: v for k, v in r.items() if not isinstance(v, (dict, list))})
c = d.get("calibration", {})
print("  calibration:", {k: c.get(k) for k in ("rms_mm", "p99_mm", "compute_time_s", "wall_s")})
p = d.get("photometric", {})
print("  photometric:", {k: v for k, v in p.items() if not isinstance(v, (dict, list))})
live = d.get("live")
if live:
    print("  live:", json.dumps(live)[:1500])
print("  phases:", json.dumps(d.get("phases"))[:800])
PY
}
if [[ " $stages " == *" lab "* ]]; then
  lab lab-show
  lab lab-kill --hold-s 3 --kill-unit 2 --kill-at-s 1 --kill-after-calibration
fi

exit 0
