# plot_cone.gp — RMSE against run time (log-log) of the cone-shadow methods,
# one panel per (scene, light), one curve per method. Called by
# kdray_bench_cone with:
#   gnuplot -e "datafile='X.dat'; outfile='X.png'; nblocks=N; titles='a b'" plot_cone.gp
# datafile holds 3 index blocks per panel (embree_rays, kd_rays, kd_cone),
# each "seconds rmse" rows with a column-header line naming the method.
if (!exists("datafile")) datafile = 'bench_cone.dat'
if (!exists("outfile")) outfile = 'bench_cone.png'
if (!exists("nblocks")) nblocks = 1
if (!exists("titles")) titles = ''
cols = (nblocks > 1) ? 2 : 1
rows = (nblocks + cols - 1) / cols
set terminal pngcairo size 640*cols, 480*rows font ",10"
set output outfile
set logscale xy
set grid
set key top right autotitle columnhead noenhanced
set xlabel "seconds (single thread, all points)"
set ylabel "RMSE vs 4096-spp reference"
set multiplot layout rows, cols
do for [i = 0:nblocks - 1] {
    set title word(titles, i + 1) noenhanced
    plot datafile index 3*i using 1:2 with linespoints lw 2 pt 7, \
         '' index 3*i + 1 using 1:2 with linespoints lw 2 pt 5, \
         '' index 3*i + 2 using 1:2 with linespoints lw 2 pt 9
}
unset multiplot
