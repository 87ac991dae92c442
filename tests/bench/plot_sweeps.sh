#!/usr/bin/env bash
# Turns the CSV files of sandtable_numerics_sweep into PNGs, next to them.
#   tests/bench/plot_sweeps.sh DIR
# Needs gnuplot (gnuplot-nox, installed by deploy/install-deps.sh); uses the pngcairo terminal
# when present (headless, no X), else png (libgd). Rows whose status is not "ok" have "nan"
# errors, which gnuplot skips; the routine's refusal shows as a gap.
set -euo pipefail

dir="${1:?usage: plot_sweeps.sh DIR (the --out DIR of sandtable_numerics_sweep)}"
command -v gnuplot >/dev/null || { echo "gnuplot not found (apt-get install gnuplot-nox)" >&2; exit 1; }
if gnuplot -e 'set terminal' 2>&1 | grep -q pngcairo; then
  terminal='pngcairo size 1200,500 font "sans,10"'
else
  terminal='png size 1200,500'
fi

plot() {  # plot NAME.png GNUPLOT-BODY
  local png="$1" body="$2"
  # A sweep whose routine refused every row has nothing to plot: warn and go on.
  if ! gnuplot 2>"${dir}/${png%.png}.gnuplot.log" <<EOF
set terminal ${terminal}
set output "${dir}/${png}"
set datafile separator ","
set datafile missing "nan"
set key top left box opaque
set grid
set format y '%g'
set format x '%g'
# A row of the routine that succeeded (status_col is set by each plot).
ok(routine) = strcol(1) eq routine && strcol(status_col) eq "ok"
any(routine) = strcol(1) eq routine
${body}
EOF
  then
    echo "warning: ${png}: gnuplot failed, see ${dir}/${png%.png}.gnuplot.log" >&2
    return 0
  fi
  echo "${dir}/${png}"
}

f="${dir}/runtime_vs_error.csv"
[[ -f "$f" ]] && plot runtime_vs_error.png "
status_col = 9
set terminal ${terminal/1200,500/1600,500}
set output '${dir}/runtime_vs_error.png'
set multiplot layout 1,3
set logscale xy
set format y '%g'
set xrange [7:15000]
set yrange [1e-3:1e4]
set title 'Run time (single core)'
set xlabel 'correspondences n'; set ylabel 'time [ms]'
plot '$f' using (ok('resection') ? \$2 : NaN):5 title 'resection (DLT + Ceres)' pt 7 ps 0.6, \
     '' using (ok('homography_dlt') ? \$2 : NaN):5 title 'homography DLT' pt 5 ps 0.6, \
     '' using (ok('homography_refined') ? \$2 : NaN):5 title 'homography DLT + refine' pt 9 ps 0.6
set ylabel 'ground-truth rms [px]'
set yrange [1e-4:100]
set key bottom left
set title 'Resection: reprojection rms on noise-free pixels'
plot for [nz in '0.1 0.5 1 2 5'] '$f' using \
       (ok('resection') && abs(\$3 - (nz+0)) < 1e-9 ? \$2 : NaN):7 \
       title 'noise '.nz.' px' pt 7 ps 0.6
set title 'Homography (DLT + refine): transfer rms on noise-free pixels'
plot for [nz in '0.1 0.5 1 2 5'] '$f' using \
       (ok('homography_refined') && abs(\$3 - (nz+0)) < 1e-9 ? \$2 : NaN):7 \
       title 'noise '.nz.' px' pt 4 ps 0.6
unset multiplot"

f="${dir}/coordinate_scale.csv"
[[ -f "$f" ]] && plot coordinate_scale.png "
status_col = 7
set logscale xy
set title 'Coordinate scale (100 points, 0.5 px noise); points and world multiplied by scale'
set xlabel 'scale'; set ylabel 'ground-truth rms [px]'
plot '$f' using (ok('homography_dlt') ? \$2 : NaN):5 title 'homography DLT' pt 5, \
     '' using (ok('resection') ? \$2 : NaN):5 title 'resection' pt 7"

f="${dir}/near_coplanar.csv"
[[ -f "$f" ]] && plot near_coplanar.png "
status_col = 8
set multiplot layout 1,2
set logscale x
set xrange [5e-7:0.5]
set xlabel 'out-of-plane spread of the 3D points [m] (0 not shown)'
set title 'Resection of near-coplanar points (200 points, 0.5 px noise)'
set logscale y
set yrange [1e-4:1e3]
set ylabel 'focal length error [%]'
plot '$f' using (ok('resection_free_intrinsics') ? \$2 : NaN):7 title 'free intrinsics' pt 7, \
     '' using (ok('resection_fixed_intrinsics') ? \$2 : NaN):7 title 'fixed intrinsics' pt 5
set ylabel 'ground-truth reprojection rms [px]'
set yrange [1e-3:1e3]
set title 'Reprojection error on noise-free pixels'
plot '$f' using (ok('resection_free_intrinsics') ? \$2 : NaN):6 title 'free intrinsics' pt 7, \
     '' using (ok('resection_fixed_intrinsics') ? \$2 : NaN):6 title 'fixed intrinsics' pt 5
unset multiplot"

f="${dir}/grazing.csv"
[[ -f "$f" ]] && plot grazing.png "
status_col = 9
set multiplot layout 1,2
set xlabel 'camera tilt from the plane normal [deg]'
set logscale y
set title 'Pose from a plane homography (200 points, 0.5 px noise, 2 m)'
set ylabel 'rotation error [deg]'
plot '$f' using (ok('homography_pose') ? \$2 : NaN):7 title 'rotation' pt 7
set ylabel 'camera centre error [mm]'
set title 'Camera centre error'
plot '$f' using (ok('homography_pose') ? \$2 : NaN):8 title 'centre' pt 5
unset multiplot"

f="${dir}/ransac_outliers.csv"
[[ -f "$f" ]] && plot ransac_outliers.png "
status_col = 11
set multiplot layout 1,2
set xlabel 'outliers [%]'
set logscale y
set title 'RANSAC error against ground truth'
set ylabel 'homography: rms [px];  plane: corner height [mm]'
plot '$f' using (ok('homography_ransac') ? \$2 : NaN):8 title 'homography (500 pts, 0.5 px)' pt 7, \
     '' using (ok('plane_ransac') ? \$2 : NaN):10 title 'plane (2000 pts, 1 mm)' pt 5
set title 'RANSAC run time'
set ylabel 'time [ms]'
plot '$f' using (ok('homography_ransac') ? \$2 : NaN):5 title 'homography' pt 7, \
     '' using (ok('plane_ransac') ? \$2 : NaN):5 title 'plane' pt 5
unset multiplot"

f="${dir}/undistortion.csv"
[[ -f "$f" ]] && plot undistortion.png "
status_col = 11
set multiplot layout 1,2
set xlabel 'k1'
set xrange [0.02:-0.82]
set title 'Pixels refused by Unproject (1280x800, fx = 1000 px)'
set ylabel 'refused [% of grid]'
plot '$f' using (any('k1_only') ? \$2 : NaN):6 with linespoints title 'k1 only' pt 7, \
     '' using (any('k1_and_k2_negative') ? \$2 : NaN):6 with linespoints title 'k2 = k1 / 2' pt 5, \
     '' using (any('k1_and_k3_positive') ? \$2 : NaN):6 with linespoints title 'k3 = +0.05' pt 9
set title 'Worst round trip of accepted pixels (Newton tolerance 1e-10 normalized = 1e-7 px)'
set ylabel 'px'
set logscale y
set format y '%.0e'
set yrange [1e-9:1e-5]
plot '$f' using (any('k1_only') ? \$2 : NaN):8 title 'k1 only' pt 7, \
     '' using (any('k1_and_k2_negative') ? \$2 : NaN):8 title 'k2 = k1 / 2' pt 5, \
     '' using (any('k1_and_k3_positive') ? \$2 : NaN):8 title 'k3 = +0.05' pt 9
unset multiplot"

f="${dir}/gl_float.csv"
[[ -f "$f" ]] && plot gl_float.png "
status_col = 7
set multiplot layout 1,2
set logscale xy
set ylabel 'float vs double [px]'
set title 'GL chain in float: scene at distance d from the projector'
set xlabel 'distance [m]'
plot '$f' using (ok('distance') ? \$2 : NaN):5 with linespoints title 'worst' pt 7, \
     '' using (ok('distance') ? \$2 : NaN):6 with linespoints title 'mean' pt 5
set title 'Scene 3 m away, table frame origin offset from the scene'
set xlabel 'offset of the scene from the origin [m]'
set xrange [0.5:20000]
plot '$f' using (ok('offset') ? \$3 : NaN):5 with linespoints title 'worst' pt 7, \
     '' using (ok('offset') ? \$3 : NaN):6 with linespoints title 'mean' pt 5
unset multiplot"

f="${dir}/triangulation.csv"
[[ -f "$f" ]] && plot triangulation.png "
status_col = 9
set multiplot layout 1,2
set logscale xy
set ylabel 'point error [mm]'
set title 'Two-view triangulation, 0.5 px noise, 2 m (refused below 1 deg)'
set xlabel 'angle between the rays at the point [deg]'
plot '$f' using (ok('angle') ? \$3 : NaN):7 title 'angle sweep' pt 7
set title 'Noise, cameras turned 40 deg apart'
set xlabel 'noise [px] (0 not shown)'
plot '$f' using (ok('noise') ? \$4 : NaN):7 title 'noise sweep' pt 5
unset multiplot"

f="${dir}/plane_fit_noise.csv"
[[ -f "$f" ]] && plot plane_fit_noise.png "
status_col = 8
set logscale xy
set title 'Least-squares plane of a 1.2 m table: worst height error at the corners'
set xlabel 'height noise [mm] (0 not shown)'; set ylabel 'corner height error [mm]'
plot for [n in '10 100 2000'] '$f' using (ok('plane_least_squares') && \$2 == n+0 ? \$3 : NaN):7 \
     title n.' points' pt 7"

f="${dir}/umeyama.csv"
[[ -f "$f" ]] && plot umeyama.png "
status_col = 9
set multiplot layout 1,2
set logscale xy
set title 'Rigid Umeyama, 16 points in a 1.2 m box'
set xlabel 'noise [mm] (0 not shown)'; set ylabel 'worst error at the box corners [mm]'
plot '$f' using (ok('box_noise') ? \$2 : NaN):7 title 'box' pt 7
set title '16 points on a 1 m line, 0.1 mm noise'
set xlabel 'perpendicular spread [mm]'; set ylabel 'rotation error [deg]'
plot '$f' using (ok('line_spread') ? \$3 : NaN):8 title 'line' pt 5
unset multiplot"

f="${dir}/table_frame.csv"
[[ -f "$f" ]] && plot table_frame.png "
status_col = 8
set title 'Table frame +x axis against the true long side (1.2 m table, 1 mm noise)'
set xlabel 'aspect ratio short / long side'; set ylabel 'x axis error [deg] (90 = flipped)'
set yrange [-5:95]
plot '$f' using (ok('table_frame') ? \$2 : NaN):6 title 'per seed' pt 7"

exit 0
