set xrange [0.954798:2102.46]
set yrange [0.0324767:1.44048]
set terminal pngcairo size 1280,860 font 'sans,10'
set output out
set title "Accuracy against cost: meniscus_rest\nreference: finest uniform bbar run (Richardson refused)" noenhanced
set logscale xy
set grid
set key top right
set xlabel 'median wall time per step (ms)'
set ylabel 'relative probe error |u - u_{ref}| / |u_{ref}| (max over probes)'
set datafile separator ','
plot 'pareto.dat' using 1:2 with points pt 7 ps 1.2 lc rgb '#4477aa' title 'case', \
     'pareto_front.dat' using 1:2 with linespoints pt 6 ps 2.2 lw 2 lc rgb '#cc3311' title 'Pareto front', \
     'pareto.dat' using 1:2:3 with labels font 'sans,7' offset 0.6,0.5 left rotate by 20 noenhanced notitle
