#!/usr/bin/env bash
# Fuzzes Sandtable's message handlers (tests/fuzz/message_handlers.h) and the glTF loader
# (common/scene/gltf_loader.h, from memory) for a bounded time.
#   deploy/fuzz.sh [seconds=60] [build_dir=build-fuzz]
#   FUZZ_GLTF_SECONDS (default 20): the glTF loader's share, run after the message handlers.
#   FUZZ_FILE_SECONDS (default 20): the share of each file-format target in FILE_TARGETS
#   (tests/fuzz/fuzz_<name>.cc, seeds tests/fuzz/<name>_corpus/), run after the glTF loader.
# With clang + libFuzzer (Debian: clang-14, libclang-rt-14-dev) it builds
# fuzz_message_handlers with ASan/UBSan and runs it over a copy of tests/fuzz/corpus/ for the
# given time; any crash is a failure (exit != 0) and leaves crash-* files in the build dir.
# Without libFuzzer it builds with the default compiler and replays the checked-in corpus and
# its mutations (fuzz_corpus_replay_test), as CI does.
set -euo pipefail
SECONDS_TO_RUN="${1:-60}"
BUILD_DIR="${2:-build-fuzz}"
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
JOBS="${FUZZ_JOBS:-2}"
GLTF_SECONDS="${FUZZ_GLTF_SECONDS:-20}"
FILE_SECONDS="${FUZZ_FILE_SECONDS:-20}"
FILE_TARGETS=(site_file json_formats session_import tracker_files)

CLANGXX="$(command -v clang++-14 || command -v clang++ || true)"
CLANGCC="$(command -v clang-14 || command -v clang || true)"
have_libfuzzer=0
if [ -n "$CLANGXX" ]; then
  probe="$(mktemp -d)"
  printf 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long){return 0;}\n' \
    > "$probe/p.cc"
  if "$CLANGXX" -fsanitize=fuzzer "$probe/p.cc" -o "$probe/p" 2>/dev/null; then have_libfuzzer=1; fi
  rm -rf "$probe"
fi

if [ "$have_libfuzzer" = 1 ]; then
  echo "fuzz: libFuzzer with $CLANGXX for ${SECONDS_TO_RUN} s"
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_C_COMPILER="$CLANGCC" -DCMAKE_CXX_COMPILER="$CLANGXX" \
    -DSANDTABLE_BUILD_FUZZERS=ON -DSANDTABLE_BUILD_BENCHMARKS=OFF > /dev/null
  file_bins=()
  for t in "${FILE_TARGETS[@]}"; do file_bins+=("fuzz_$t"); done
  ninja -C "$BUILD_DIR" -j"$JOBS" fuzz_message_handlers fuzz_gltf_loader "${file_bins[@]}"
  work="$BUILD_DIR/fuzz-corpus"
  mkdir -p "$work"
  cp -n tests/fuzz/corpus/* "$work/" 2>/dev/null || true
  (cd "$BUILD_DIR" && ./tests/fuzz/fuzz_message_handlers -max_total_time="$SECONDS_TO_RUN" \
     -max_len=65536 -rss_limit_mb=2048 -print_final_stats=1 fuzz-corpus)
  echo "fuzz: glTF loader for ${GLTF_SECONDS} s"
  gltf_work="$BUILD_DIR/fuzz-gltf-corpus"
  mkdir -p "$gltf_work"
  cp -n tests/fuzz/gltf_corpus/* "$gltf_work/" 2>/dev/null || true
  # -timeout: one input taking over 10 s is a finding (a hang), as is growing past 2 GB.
  (cd "$BUILD_DIR" && ./tests/fuzz/fuzz_gltf_loader -max_total_time="$GLTF_SECONDS" \
     -max_len=65536 -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 fuzz-gltf-corpus)
  for t in "${FILE_TARGETS[@]}"; do
    echo "fuzz: $t for ${FILE_SECONDS} s"
    mkdir -p "$BUILD_DIR/fuzz-$t-corpus"
    cp -n "tests/fuzz/${t}_corpus/"* "$BUILD_DIR/fuzz-$t-corpus/" 2>/dev/null || true
    (cd "$BUILD_DIR" && "./tests/fuzz/fuzz_$t" -max_total_time="$FILE_SECONDS" \
       -max_len=65536 -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 "fuzz-$t-corpus")
  done
  echo "fuzz: no findings in ${SECONDS_TO_RUN} s + ${GLTF_SECONDS} s (glTF)" \
    "+ ${#FILE_TARGETS[@]} x ${FILE_SECONDS} s (file formats)"
else
  echo "fuzz: libFuzzer not available; replaying tests/fuzz/corpus and tests/fuzz/gltf_corpus"
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo > /dev/null
  replays=(fuzz_corpus_replay_test fuzz_gltf_corpus_replay_test)
  for t in "${FILE_TARGETS[@]}"; do replays+=("fuzz_${t}_replay_test"); done
  ninja -C "$BUILD_DIR" -j"$JOBS" "${replays[@]}"
  for r in "${replays[@]}"; do "$BUILD_DIR/tests/fuzz/$r"; done
fi
