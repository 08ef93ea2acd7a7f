"""PFM reading and writing for the bench scripts: top-down (H, W, C) arrays, as the C++ tools keep
them (PFM rows run bottom-up)."""
import numpy as np


def read_pfm(path, dtype=np.float32):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        channels = 3 if kind == b"PF" else 1
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4", count=w * h * channels)
    return data.reshape(h, w, channels)[::-1].astype(dtype)


def write_pfm(path, image):
    """image: (H, W, 3) or (H, W) or (H, W, 1); written as little-endian float."""
    image = np.asarray(image, dtype="<f4")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    h, w = image.shape[:2]
    with open(path, "wb") as f:
        f.write(b"%s\n%d %d\n-1.0\n" % (b"PF" if image.ndim == 3 else b"Pf", w, h))
        f.write(np.ascontiguousarray(image[::-1]).tobytes())
