#!/usr/bin/env bash
# Plots DIR/structured_light_sweep.csv (written by structured_light_sweep) into
# DIR/structured_light_sweep.png (four panels: error against each swept parameter) and
# DIR/structured_light_tradeoff.png (error against modeled device time, every setting).
#   tests/bench/plot_structured_light_sweep.sh DIR
set -euo pipefail
dir="${1:?usage: plot_structured_light_sweep.sh DIR}"
csv="$dir/structured_light_sweep.csv"
[[ -f "$csv" ]] || { echo "no $csv (run structured_light_sweep --out $dir first)" >&2; exit 1; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
# Writes the ok rows of group $1 (and optional extra awk condition $2) to a file named after
# the selection (it runs in a $(...) subshell, so no counter); prints the file's name.
sel() {
  local name
  name="$(echo "$1 ${2:-}" | tr -c 'A-Za-z0-9' '_')"
  awk -F, "NR > 1 && \$1 == \"$1\" && \$16 == \"ok\" ${2:+&& $2}" "$csv" > "$tmp/$name.csv"
  echo "$tmp/$name.csv"
}

gnuplot <<GP
set terminal pngcairo size 1400,1000 font ",11"
set output "$dir/structured_light_sweep.png"
set datafile separator ","
set termoption noenhanced
set multiplot layout 2,2 title "Structured light in the simulated world: error against settings (2-D RMS vs true projector pixel)"
set grid
set logscale y
set ylabel "error, projector px"
set key top left

set title "Gray bits skipped (finest first)"
set xlabel "gray_lsb_skip (cell = 2^skip px)"
set xtics 1
plot "$(sel gray_bits '$3 == 0')" using 2:12 with linespoints lw 2 title "Gray only, rms", \
     "$(sel gray_bits '$3 == 8')" using 2:12 with linespoints lw 2 title "Gray + 8-step phase, rms", \
     "$(sel gray_bits '$3 == 8')" using 2:13 with linespoints dt 2 title "Gray + 8-step phase, p99"

set title "Phase steps N (period 16 px)"
set xlabel "N"
set xtics auto
plot "$(sel phase_steps '$2 == 0')" using 3:12 with linespoints lw 2 title "full Gray, rms", \
     "$(sel phase_steps '$2 == 0')" using 3:13 with linespoints dt 2 title "full Gray, p99", \
     "$(sel phase_steps '$2 == 2')" using 3:12 with linespoints lw 2 title "Gray skip 2, rms"

set title "Phase period P (8 steps, full Gray)"
set xlabel "P, projector px"
set logscale x 2
plot "$(sel period)" using 4:12 with linespoints lw 2 title "rms", \
     "$(sel period)" using 4:13 with linespoints dt 2 title "p99"
unset logscale x

set title "Camera noise (preset: 0.5 DN read noise, 10000 e- full well)"
set xlabel "read noise, DN (photon-noise variance x same factor; 0 = noise off)"
plot "$(sel noise '$3 == 0 && $8 >= 0.005')" using 6:12 with linespoints lw 2 title "Gray only", \
     "$(sel noise '$3 == 4 && $8 >= 0.005')" using 6:12 with linespoints lw 2 title "Gray + 4-step", \
     "$(sel noise '$3 == 8 && $8 >= 0.005')" using 6:12 with linespoints lw 2 title "Gray + 8-step"
unset multiplot

set output "$dir/structured_light_tradeoff.png"
set terminal pngcairo size 1100,750 font ",11" noenhanced
set title "Error against modeled device time (frames / 60 Hz + capture latency), default noise"
set xlabel "device time, s"
set ylabel "2-D rms error, projector px"
unset logscale x
set logscale y
set key top right
plot "$(sel gray_bits '$3 == 0')" using 10:12:2 with labels offset 0,1 notitle, \
     "$(sel gray_bits '$3 == 0')" using 10:12 with points pt 7 ps 1.5 title "Gray only (label: bits skipped)", \
     "$(sel phase_steps '$2 == 0')" using 10:12:3 with labels offset 0,1 notitle, \
     "$(sel phase_steps '$2 == 0')" using 10:12 with points pt 5 ps 1.5 title "full Gray + N-step phase (label: N)", \
     "$(sel phase_steps '$2 == 2')" using 10:12:3 with labels offset 0,-1 notitle, \
     "$(sel phase_steps '$2 == 2')" using 10:12 with points pt 9 ps 1.5 title "Gray skip 2 + N-step phase (label: N)"
GP
echo "wrote $dir/structured_light_sweep.png $dir/structured_light_tradeoff.png"
