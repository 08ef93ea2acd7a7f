"""PFM reading for the bench scripts: top-down (H, W, C) arrays, as the C++ tools keep them."""
import numpy as np


def read_pfm(path, dtype=np.float32):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        channels = 3 if kind == b"PF" else 1
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    return data.reshape(h, w, channels)[::-1].astype(dtype)  # PFM rows run bottom-up
