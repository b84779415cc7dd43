"""numpy side of the precompute benchmark: the MODEL.md formula
D_n = fftshift(N_x*N_y*ifft2((1j*h)**n)) for n = 0..T on the same height field.

usage: python3 numpy_terms.py FIELD.f64 NX NY T REPEATS
prints the best wall time in seconds and the DC magnitudes of a few terms (a checksum
the Rust side compares against its own terms)."""
import sys
import time

import numpy as np

path, nx, ny, t, repeats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
h = np.fromfile(path, dtype="<f8").reshape(ny, nx)
h = h - h.mean()
best = float("inf")
for _ in range(repeats):
    start = time.perf_counter()
    terms = [np.fft.fftshift(nx * ny * np.fft.ifft2((1j * h) ** n)) for n in range(t + 1)]
    best = min(best, time.perf_counter() - start)
check = [abs(terms[n][ny // 2, nx // 2]) / (nx * ny) for n in (0, 1, 2, t)]
print(f"{best:.6f}", " ".join(f"{c:.12e}" for c in check))
