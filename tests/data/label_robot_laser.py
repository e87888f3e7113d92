"""Hand-labelling aid for the robot-laser frames (../shared/realdata/robot-laser).

usage: label_robot_laser.py FRAME ROW_GUESS COLUMN... -> writes /tmp/label_FRAME.png

For each COLUMN the panel shows the 9 columns around it (the labelled one boxed in blue) over
rows ROW_GUESS-20..ROW_GUESS+20 at 10x, with a tick every row and the row number every 2 rows,
so that a person reads off the row of the laser line's centre in that column and writes it into
robot_laser_labels.csv as `frame,column,row`. It also prints each column's profile (red minus
the mean of green and blue, averaged over the column and its two neighbours) around the guess,
to check the reading against. Nothing here looks at the detector's output.
"""
import sys

import numpy as np
from PIL import Image, ImageDraw

frame, guess = int(sys.argv[1]), int(sys.argv[2])
cols = [int(c) for c in sys.argv[3:]]
img = np.asarray(Image.open(f"../shared/realdata/robot-laser/img{frame:04d}.jpg"))
z, half = 8, 28
r0, r1 = max(0, guess - half), min(img.shape[0], guess + half + 1)
panel_w = 9 * z + 40
canvas = Image.new("RGB", (panel_w * len(cols), (r1 - r0) * z + 14), "white")
d = ImageDraw.Draw(canvas)
for k, col in enumerate(cols):
    c0 = col - 4
    crop = Image.fromarray(img[r0:r1, c0 : c0 + 9]).resize((9 * z, (r1 - r0) * z), Image.NEAREST)
    x0 = k * panel_w + 36
    canvas.paste(crop, (x0, 14))
    d.text((x0, 0), f"col {col}", fill="black")
    for r in range(r0, r1):
        y = 14 + (r - r0) * z + z // 2
        d.line([(x0 - 6, y), (x0, y)], fill="black")
        if r % 2 == 0:
            d.text((x0 - 34, y - 5), str(r), fill="black")
    d.rectangle([x0 + 4 * z, 14, x0 + 5 * z - 1, canvas.height - 1], outline="blue")
canvas.save(f"/tmp/label_{frame}.png")
for col in cols:
    c = img[:, col - 1 : col + 2].astype(float).mean(1)
    rmo = c[:, 0] - 0.5 * (c[:, 1] + c[:, 2])
    print(f"column {col}: " + " ".join(f"{r}:{rmo[r]:.0f}" for r in range(r0, r1)))
