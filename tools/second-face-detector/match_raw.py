#!/usr/bin/env python3
"""Of the finds count_faces.py made outside the raw folder, how many lie on a raw find
(IoU >= 0.3): faces the camera or the enhancer left where a face was, not textures.
Usage: match_raw.py COUNTS.csv ROOT (the folders named in the CSV header, under ROOT)."""
import csv, os, sys, cv2
import importlib.util
spec = importlib.util.spec_from_file_location("cf", os.path.join(os.path.dirname(os.path.abspath(__file__)), "count_faces.py")); cf = importlib.util.module_from_spec(spec); spec.loader.exec_module(cf)
dets = [cv2.CascadeClassifier(os.path.join(cv2.data.haarcascades, c)) for c in cf.CASCADES]
def boxes(path):
    img = cv2.imread(path); g = cv2.equalizeHist(cv2.resize(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), None, fx=1.5, fy=1.5))
    out = []
    for i, d in enumerate(dets):
        for (x,y,w,h) in d.detectMultiScale(g, scaleFactor=1.15, minNeighbors=5, minSize=(24,24)): out.append((x,y,x+w,y+h))
        if i == len(dets)-1:
            W = g.shape[1]
            for (x,y,w,h) in d.detectMultiScale(cv2.flip(g,1), scaleFactor=1.15, minNeighbors=5, minSize=(24,24)): out.append((W-x-w,y,W-x,y+h))
    return out
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
