set terminal pngcairo size 1400,1450 font 'sans,10'
set output out
set multiplot layout 5,1 title "Stability matrix: cube_1cm (level 2, 0.2 s per cell)" font 'sans,13' noenhanced
set palette defined (0 '#228833', 1 '#99cc66', 2 '#ccbb44', 3 '#ee7733', 4 '#cc3311', 5 '#661100', 6 '#bbbbbb')
set palette maxcolors 7
set cbrange [-0.5:6.5]
set cbtics ('ok' 0, 'recovered' 1, 'failed steps' 2, 'energy rises' 3, 'not bounded' 4, 'not finite' 5, 'missing' 6)
set xrange [-0.5:19.5]
set yrange [-0.5:3.5]
set xtics ('E 1e+02 Pa, ν 0' 0, 'E 1e+02 Pa, ν 0.3' 1, 'E 1e+02 Pa, ν 0.45' 2, 'E 1e+02 Pa, ν 0.49' 3, 'E 1e+02 Pa, ν 0.499' 4, 'E 1e+04 Pa, ν 0' 5, 'E 1e+04 Pa, ν 0.3' 6, 'E 1e+04 Pa, ν 0.45' 7, 'E 1e+04 Pa, ν 0.49' 8, 'E 1e+04 Pa, ν 0.499' 9, 'E 1e+06 Pa, ν 0' 10, 'E 1e+06 Pa, ν 0.3' 11, 'E 1e+06 Pa, ν 0.45' 12, 'E 1e+06 Pa, ν 0.49' 13, 'E 1e+06 Pa, ν 0.499' 14, 'E 1e+09 Pa, ν 0' 15, 'E 1e+09 Pa, ν 0.3' 16, 'E 1e+09 Pa, ν 0.45' 17, 'E 1e+09 Pa, ν 0.49' 18, 'E 1e+09 Pa, ν 0.499' 19) rotate by 35 right font 'sans,7'
set ytics ('0.0001' 0, '0.001' 1, '0.01' 2, '0.05' 3)
set ylabel 'time step Δt (s)'
set xlabel 'Young modulus E (Pa) and Poisson ratio ν'
unset key
set title 'scenario: sag'
plot 'stability_sag.dat' using 1:2:3 with image title 'sag'
set title 'scenario: crush'
plot 'stability_crush.dat' using 1:2:3 with image title 'crush'
set title 'scenario: twist'
plot 'stability_twist.dat' using 1:2:3 with image title 'twist'
set title 'scenario: punch'
plot 'stability_punch.dat' using 1:2:3 with image title 'punch'
set title 'scenario: press'
plot 'stability_press.dat' using 1:2:3 with image title 'press'
unset multiplot
