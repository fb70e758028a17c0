#!/usr/bin/env python3
"""Draw a packing dumped by tests/test_packing.cpp (DISABLED_Report test) as SVG.

    DEFORMIX_PACKING_DUMP=/tmp/dump ./test_packing \
        --gtest_also_run_disabled_tests --gtest_filter='*Report*'
    python3 scripts/plot_packing.py /tmp/dump/packing_1500_1.txt out.svg

Input: first line "x_left x_right y_bottom y_top", then one line per disk
"x y r rattler" (rattler = 1 if the disk has < 3 contacts, iterated, with
contact = gap < 1e-4 <d>). Rattlers are red, the walls blue. Standard
library only (no matplotlib).
"""
import sys


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    with open(sys.argv[1]) as f:
        xl, xr, yb, yt = map(float, f.readline().split())
        disks = [line.split() for line in f if line.strip()]
    pad = 0.5
    scale = 800.0 / max(xr - xl + 2 * pad, yt - yb + 2 * pad)
    w = (xr - xl + 2 * pad) * scale
    h = (yt - yb + 2 * pad) * scale

    def sx(x):
        return (x - xl + pad) * scale

    def sy(y):  # SVG y axis points down
        return (yt + pad - y) * scale

    nr = sum(1 for d in disks if len(d) > 3 and d[3] == "1")
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0f}" height="{h + 30:.0f}">',
           f'<rect width="100%" height="100%" fill="white"/>',
           f'<text x="10" y="{h + 20:.0f}" font-size="16">{len(disks)} disks, {nr} rattlers (red)</text>']
    for d in disks:
        x, y, r = float(d[0]), float(d[1]), float(d[2])
        fill = "#d62728" if len(d) > 3 and d[3] == "1" else "#c0c0c0"
        out.append(f'<circle cx="{sx(x):.2f}" cy="{sy(y):.2f}" r="{r * scale:.2f}" fill="{fill}" '
                   f'stroke="black" stroke-width="0.4"/>')
    out.append(f'<rect x="{sx(xl):.2f}" y="{sy(yt):.2f}" width="{(xr - xl) * scale:.2f}" '
               f'height="{(yt - yb) * scale:.2f}" fill="none" stroke="blue" stroke-width="1.5"/>')
    out.append("</svg>")
    with open(sys.argv[2], "w") as f:
        f.write("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
