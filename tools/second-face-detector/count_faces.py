#!/usr/bin/env python3
"""Counts faces with a detector campro does not use (OpenCV's Haar cascades, frontal and
profile), so the enhanced view's face guard (YuNet) is checked by a second opinion.

Usage: count_faces.py RAW_DIR OTHER_DIR... [--csv OUT.csv]
Every image of RAW_DIR is matched by file stem in each OTHER_DIR (captured, enhanced, ...);
each image is enlarged 1.5x (so a 16-pixel face meets the cascade's 24-pixel window) and
searched with scaleFactor 1.15, minNeighbors 5. Prints, per folder, the faces found, the
images with any face, and (against the second folder, the captured one) the images where a
later folder shows more faces than it. Needs `pip install "opencv-python-headless<5"`
(OpenCV 5 no longer ships the cascades).
"""
import csv
import os
import sys

import cv2

CASCADES = ["haarcascade_frontalface_default.xml", "haarcascade_profileface.xml"]


def detectors():
    """The cascades, loaded; one line naming the fix when OpenCV lacks them."""
    ds = [cv2.CascadeClassifier(os.path.join(cv2.data.haarcascades, c)) for c in CASCADES]
    if any(d.empty() for d in ds):
        raise SystemExit("the Haar cascades are missing: pip install 'opencv-python-headless<5'")
    return ds


def boxes(detectors, path):
    """Every find in the image at `path`, as (x0, y0, x1, y1) in the enlarged image's pixels:
    each cascade, and the profile one on the mirrored image too (faces turned the other way)."""
    img = cv2.imread(path, cv2.IMREAD_COLOR)
    if img is None:
        raise SystemExit(f"{path}: not an image OpenCV reads")
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    grey = cv2.resize(grey, None, fx=1.5, fy=1.5, interpolation=cv2.INTER_LINEAR)
    grey = cv2.equalizeHist(grey)
    width = grey.shape[1]
    out = []
    for d in detectors:
        for (x, y, w, h) in d.detectMultiScale(grey, scaleFactor=1.15, minNeighbors=5, minSize=(24, 24)):
            out.append((x, y, x + w, y + h))
        if d is detectors[-1]:
            for (x, y, w, h) in d.detectMultiScale(cv2.flip(grey, 1), scaleFactor=1.15, minNeighbors=5, minSize=(24, 24)):
                out.append((width - x - w, y, width - x, y + h))
    return out


def count(detectors, path):
    return len(boxes(detectors, path))


def stems(folder):
    out = {}
    for f in sorted(os.listdir(folder)):
        stem, ext = os.path.splitext(f)
        if ext.lower() in (".jpg", ".jpeg", ".png"):
            out[stem] = os.path.join(folder, f)
    return out


def main(argv):
    csv_out = None
    if "--csv" in argv:
        i = argv.index("--csv")
        csv_out = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    if len(argv) < 2:
        raise SystemExit(__doc__)
    ds = detectors()
    folders = [stems(f) for f in argv]
    names = sorted(set.intersection(*(set(f) for f in folders)))
    rows = []
    for name in names:
        rows.append([name] + [count(ds, f[name]) for f in folders])
    print(f"{len(names)} images in all {len(argv)} folders")
    for j, folder in enumerate(argv):
        faces = sum(r[j + 1] for r in rows)
        with_any = sum(1 for r in rows if r[j + 1] > 0)
        more = sum(1 for r in rows if j >= 2 and r[j + 1] > r[2]) if len(argv) > 1 else 0
        line = f"{folder}: {faces} faces, {with_any} images with a face"
        if j >= 2:
            line += f", {more} images with more faces than {argv[1]}"
        print(line)
    if csv_out:
        with open(csv_out, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["image"] + argv)
            w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1:])
