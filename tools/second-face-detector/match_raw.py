#!/usr/bin/env python3
"""Of the finds count_faces.py made outside the raw folder, how many lie on a raw find
(IoU >= 0.3): faces the camera or the enhancer left where a face was, not textures.
Usage: match_raw.py COUNTS.csv ROOT (the folders named in the CSV header, under ROOT)."""
import csv, os, sys, cv2
import importlib.util
spec = importlib.util.spec_from_file_location("cf", os.path.join(os.path.dirname(os.path.abspath(__file__)), "count_faces.py")); cf = importlib.util.module_from_spec(spec); spec.loader.exec_module(cf)
dets = cf.detectors()
def boxes(path):
    return cf.boxes(dets, path)
def iou(a,b):
    ix=max(0,min(a[2],b[2])-max(a[0],b[0])); iy=max(0,min(a[3],b[3])-max(a[1],b[1])); i=ix*iy
    u=(a[2]-a[0])*(a[3]-a[1])+(b[2]-b[0])*(b[3]-b[1])-i
    return i/u if u>0 else 0
rows = list(csv.reader(open(sys.argv[1])))
head, rows = rows[0], rows[1:]
folders = head[1:]
todo = [r[0] for r in rows if any(int(v) > 0 for v in r[2:])]
tot = {f: 0 for f in folders[1:]}
for name in todo:
    raw = boxes(os.path.join(sys.argv[2], folders[0], name + '.jpg'))
    for f in folders[1:]:
        b = boxes(os.path.join(sys.argv[2], f, name + '.jpg'))
        tot[f] += sum(1 for x in b if any(iou(x, r) >= 0.3 for r in raw))
print(len(todo), 'images with a find outside raw')
for f, n in tot.items(): print(f, n, 'finds at a raw find (IoU >= 0.3)')
