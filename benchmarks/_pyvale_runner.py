"""Run pyvale's 2-D DIC on saved images (called by bench_dic.py with pyvale's interpreter).

Usage: python _pyvale_runner.py WORKDIR SHAPE THREADS REPEATS; reads WORKDIR/ref.npy and
cur.npy, writes WORKDIR/<SHAPE>/dic_results_def_img_0000.csv and prints the best time (s).
"""

import sys
import time
from pathlib import Path

import numpy as np
import pyvale.dic as dic

work = Path(sys.argv[1])
shape, threads, repeats = sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
ref = np.load(work / "ref.npy").astype(np.float32)
cur = np.load(work / "cur.npy").astype(np.float32)
mask = np.zeros(ref.shape, bool)
mask[1:-1, 1:-1] = True
out = work / shape
out.mkdir(exist_ok=True)
best = float("inf")
for _ in range(repeats):
    t0 = time.perf_counter()
    dic.calculate_2d(
        ref,
        cur,
        mask,
        seed=[(ref.shape[1] // 2, ref.shape[0] // 2)],
        subset_size=21,
        subset_step=10,
        shape_function=shape,
        num_threads=threads,
        output_basepath=str(out),
        print_level=0,
        precision=1e-4,
        threshold=0.6,
    )
    best = min(best, time.perf_counter() - t0)
print(best)
