"""How the per-pixel restoration table's bins limit it (docs/enhancer.md, "Equal-mass bins").

Fits E[raw | captured bin] on half the COCO training images (every third pixel a side) and
scores the table alone against raw on the held-out images (COCO id % 5 == 0), mean PSNR per
image, for several binnings. A simplified fit: each bin shrunk toward the prior's mean colour
with 4 pseudo-pixels (campro_eval::restore shrinks toward the coarser bin instead).

    campro simulate params/campro-omega-0.5.json ../shared/data/coco-person/images -o cap/ --image-format png
    python3 docs/scripts/restore-bins.py cap/ ../shared/data/coco-person/images

Needs numpy and Pillow (pip install numpy pillow).
"""
import os
import sys

import numpy as np
from PIL import Image

cap_dir, raw_dir = sys.argv[1], sys.argv[2]
files = sorted(f for f in os.listdir(cap_dir) if f.endswith(".png"))
train = [f for f in files if int(f[:-4]) % 5 != 0]
held = [f for f in files if int(f[:-4]) % 5 == 0]


def load(f):
    c = np.asarray(Image.open(os.path.join(cap_dir, f)).convert("RGB"))
    r = np.asarray(Image.open(os.path.join(raw_dir, f[:-4] + ".jpg")).convert("RGB"))
    return c, r


C, R = [], []
for f in train[::2]:
    c, r = load(f)
    C.append(c[::3, ::3].reshape(-1, 3))
    R.append(r[::3, ::3].reshape(-1, 3))
C = np.concatenate(C).astype(np.int64)
R = np.concatenate(R).astype(np.float64)
H = [load(f) for f in held]
print(f"{len(C)} training pixels, {len(H)} held-out images")
for ch in range(3):
    h = np.bincount(C[:, ch], minlength=256)
    busy = h > len(C) * 1e-3
    print(f"channel {ch}: {busy.sum()} levels hold more than 0.1% of the pixels each, {h[busy].sum() / len(C):.1%} together")


def score(qs, name):
    sides = [int(q.max()) + 1 for q in qs]

    def index(c):
        return (qs[0][c[:, 0]] * sides[1] + qs[1][c[:, 1]]) * sides[2] + qs[2][c[:, 2]]

    n_bins = sides[0] * sides[1] * sides[2]
    idx = index(C)
    n = np.bincount(idx, minlength=n_bins).astype(float)
    mean = R.mean(0)
    tab = np.stack([(np.bincount(idx, weights=R[:, k], minlength=n_bins) + 4 * mean[k]) / (n + 4) for k in range(3)], 1)
    ps = []
    for c, r in H:
        out = np.clip(np.round(tab[index(c.astype(np.int64).reshape(-1, 3))]), 0, 255)
        ps.append(10 * np.log10(255**2 / ((out - r.reshape(-1, 3)) ** 2).mean()))
    print(f"{name}: {n_bins} bins, held-out PSNR {np.mean(ps):.2f} dB")


def equal_mass(ch, k):
    # campro_eval::restore::Binning::equal_mass, level by level.
    h = np.bincount(C[:, ch], minlength=256).astype(np.int64)
    rest, q, b, acc = int(h.sum()), np.zeros(256, np.int64), 0, 0
    for v in range(256):
        sharing = k - b
        over, under = (acc + h[v]) * sharing - rest, rest - acc * sharing
        if acc > 0 and b < k - 1 and over > 0 and over > under:
            rest, acc, b = rest - acc, 0, b + 1
        q[v] = b
        acc += int(h[v])
        if b < k - 1 and ((acc > 0 and acc * (k - b) >= rest) or 255 - v <= k - 1 - b):
            rest, acc, b = rest - acc, 0, b + 1
    return q


def uniform(bits):
    return np.arange(256) >> (8 - bits)


score([uniform(6)] * 3, "equal-width, 64 a channel")
score([uniform(7)] * 3, "equal-width, 128 a channel")
score([equal_mass(c, 64) for c in range(3)], "equal-mass, 64 a channel")
score([equal_mass(c, 76) for c in range(3)], "equal-mass, 76 a channel")
score([uniform(8)] * 3, "one bin per 8-bit colour")
