"""The seed's blob detection and blob selection (chapter 9) in numpy: the units of the
Python tutorial (tutorial.py), and the units a system file can run as supervised
workers:

    [[unit]]
    name = "BlobDetection"
    python = "blobs.py:BlobDetection"

Each class says its types (`output_type`, `input_types`), which `python -m
esgm.worker` registers it with."""

import numpy as np

THRESHOLD = 127         # luminance of a blob's pixel (above)
MIN_SIZE = 10           # pixels of the smallest blob


def detect(image):
    """Blobs of an (h, w, 3) image as (x, y, size), largest first, as the Rust unit finds
    them (cu-workers): pixels whose BT.601 luminance is above 127, 8-connected, at
    least 10 of them; labelled by propagating the smallest label, all in numpy."""
    rgb = image.astype(np.uint32)
    luminance = (77 * rgb[..., 0] + 150 * rgb[..., 1] + 29 * rgb[..., 2] + 128) >> 8
    mask = luminance > THRESHOLD
    big = np.iinfo(np.int64).max
    labels = np.where(mask, np.arange(mask.size).reshape(mask.shape), big)
    while True:
        p = np.pad(labels, 1, constant_values=big)
        neighbours = [p[dy:dy + mask.shape[0], dx:dx + mask.shape[1]] for dy in range(3) for dx in range(3)]
        smallest = np.where(mask, np.minimum.reduce(neighbours), big)
        if np.array_equal(smallest, labels):
            break
        labels = smallest
    blobs = []
    for label in np.unique(labels[mask]):
        ys, xs = np.nonzero(labels == label)
        if xs.size >= MIN_SIZE:
            blobs.append((int(xs.mean()), int(ys.mean()), int(xs.size)))
    return sorted(blobs, key=lambda b: -b[2])


class BlobDetection:
    """Image -> BlobSeq (the seed's BlobDetection unit)."""

    output_type = "BlobSeq"
    input_types = ["Image"]

    def compute(self, inputs, qtime):
        image = inputs[0]
        items = [{"name": f"blob{i}", "x": x, "y": y, "size": s} for i, (x, y, s) in enumerate(detect(image["image_data"]))]
        return ("blobs", image.valid_time, {"items": items})


class BlobSelection:
    """BlobSeq -> Blob: the largest (the seed's BlobSelection unit)."""

    output_type = "Blob"
    input_types = ["BlobSeq"]

    def compute(self, inputs, qtime):
        seq = inputs[0]
        if not seq["items"]:
            return None
        b = seq["items"][0]
        return ("current_blob", seq.valid_time, {"x": b["x"], "y": b["y"], "size": b["size"]})
