// The colour maps of the pressure maps: matplotlib's viridis and cividis (CC0), 32 stops
// each, interpolated linearly; tests/monitor/test_playback.py checks them against matplotlib.
// Both are perceptually uniform and readable with the common colour-vision deficiencies.
"use strict";
const COLORMAPS = {
  viridis: [
    [68, 1, 84], [71, 13, 96], [72, 24, 106], [72, 35, 116], [71, 46, 124], [69, 56, 130], [66, 65, 134], [62, 74, 137],
    [58, 84, 140], [54, 93, 141], [50, 101, 142], [46, 109, 142], [43, 117, 142], [40, 125, 142], [37, 132, 142], [34, 140, 141],
    [31, 148, 140], [30, 156, 137], [32, 163, 134], [37, 171, 130], [46, 179, 124], [58, 186, 118], [72, 193, 110], [88, 199, 101],
    [108, 205, 90], [127, 211, 78], [147, 215, 65], [168, 219, 52], [192, 223, 37], [213, 226, 26], [234, 229, 26], [253, 231, 37],
  ],
  cividis: [
    [0, 34, 78], [0, 40, 91], [0, 46, 106], [5, 51, 113], [28, 57, 111], [41, 63, 110], [51, 68, 109], [60, 74, 108],
    [69, 80, 108], [77, 85, 108], [85, 91, 109], [92, 97, 110], [100, 103, 112], [107, 109, 114], [114, 114, 116], [120, 120, 119],
    [128, 127, 120], [136, 133, 120], [144, 139, 120], [151, 145, 119], [160, 152, 117], [168, 158, 115], [176, 165, 113], [185, 171, 109],
    [194, 179, 105], [203, 185, 101], [211, 192, 95], [220, 200, 89], [230, 208, 81], [239, 215, 72], [248, 223, 60], [254, 232, 56],
  ],
};
// the colour of f in [0, 1] (clipped) on the map `name`; not a number: light grey
function colourOf(name, f) {
  if (!Number.isFinite(f)) return "#e5e7eb";
  const stops = COLORMAPS[name] || COLORMAPS.viridis, n = stops.length - 1;
  const x = Math.min(Math.max(f, 0), 1) * n, i = Math.min(Math.floor(x), n - 1), t = x - i;
  const c = stops[i].map((v, k) => Math.round(v + t * (stops[i + 1][k] - v)));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}
