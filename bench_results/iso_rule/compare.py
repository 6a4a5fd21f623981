"""Means over the same shapes, the rows in this folder (the mesher's automatic iso-value at one
voxel unless the cover is shredded) against the same rows of another folder (Table I's, made when
handles raised it to 1.95 voxels): python bench_results/iso_rule/compare.py bench_results/table1"""
import glob
import json
import os
import sys

here = os.path.dirname(os.path.abspath(__file__))
keys = ["cd_l1_x100", "f1_0.005", "nc", "double_layer", "area_ratio", "area_ratio_thin_once"]
for path in sorted(glob.glob(os.path.join(here, "*.json"))):
    name = os.path.basename(path)
    new = [s for s in json.load(open(path))["shapes"] if not s["failed"]]
    old_all = {s["shape_seed"]: s for s in json.load(open(os.path.join(sys.argv[1], name)))["shapes"]}
    old = [old_all[s["shape_seed"]] for s in new]
    mean = lambda rows, k: sum(r[k] for r in rows) / len(rows)
    print(f"{name[:-5]:28s} n={len(new)} " + "  ".join(
        f"{k}: {mean(old, k):.4f} -> {mean(new, k):.4f}" for k in keys))
