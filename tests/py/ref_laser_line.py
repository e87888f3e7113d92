"""Independent reference for the laser-line tests on real frames: per image row, the centre of the
laser line from a least-squares Gaussian fit (scipy) on the background-subtracted on/off pair.

usage: ref_laser_line.py ON.png OFF.png [channel]
prints JSON {"rows": [centre or null, ...], "amplitude": [...], "sigma": [...]}

The fit model is b + a exp(-(x - c)^2 / (2 s^2)) over a window of +-8 px around the row's largest
difference (red channel, or the one named), then fitted again over +-3 s where that is wider: the
window holds the line's tails, whose sigma reaches 6-8 px on the Ciclop's saturated line (over
+-8 px alone, 9 % of its rows lay more than 0.3 px from where the wider window puts them). A row
has a line when the fitted amplitude is at least 25 grey levels and 5 times the row's robust noise
(the median absolute difference away from the peak), and the fit converged with a width between
0.3 and 8 px.
"""
import json
import sys

import numpy as np
from PIL import Image
from scipy.optimize import curve_fit

CHANNELS = {"red": 0, "green": 1, "blue": 2}


def gauss(x, b, a, c, s):
    return b + a * np.exp(-0.5 * ((x - c) / s) ** 2)


def main():
    on = np.asarray(Image.open(sys.argv[1])).astype(float)
    off = np.asarray(Image.open(sys.argv[2])).astype(float)
    ch = CHANNELS[sys.argv[3]] if len(sys.argv) > 3 else 0
    diff = (on - off)[..., ch] if on.ndim == 3 else on - off
    rows, amps, sigmas = [], [], []
    half = 8
    for row in diff:
        m = int(np.argmax(row))
        lo, hi = max(0, m - half), min(len(row), m + half + 1)
        away = np.concatenate([row[: max(0, m - 20)], row[m + 21 :]])
        noise = 1.4826 * np.median(np.abs(away - np.median(away))) if away.size else 0.0
        x = np.arange(lo, hi, dtype=float)
        y = row[lo:hi]
        centre = None
        amp = sig = 0.0
        if hi - lo >= 7 and row[m] > 0:
            try:
                p, _ = curve_fit(gauss, x, y, p0=[0.0, row[m], float(m), 1.5], maxfev=2000)
                wide = int(np.ceil(3.0 * abs(p[3])))
                if wide > half:
                    lo, hi = max(0, m - wide), min(len(row), m + wide + 1)
                    x = np.arange(lo, hi, dtype=float)
                    p, _ = curve_fit(gauss, x, row[lo:hi], p0=p, maxfev=2000)
                b, a, c, s = p
                s = abs(s)
                if a >= 25.0 and a >= 5.0 * noise and 0.3 <= s <= 8.0 and lo <= c <= hi - 1:
                    centre, amp, sig = float(c), float(a), float(s)
            except RuntimeError:
                pass
        rows.append(centre)
        amps.append(amp)
        sigmas.append(sig)
    print(json.dumps({"rows": rows, "amplitude": amps, "sigma": sigmas}))


if __name__ == "__main__":
    main()
