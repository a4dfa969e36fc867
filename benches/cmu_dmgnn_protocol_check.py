#!/usr/bin/env python3
"""Independent check of the CMU (DMGNN preprocessing) test protocol.

Written from the protocol as described in crates/eval/README.md ("CMU (DMGNN
preprocessing)"), numpy only, without the Rust code: it prints, per complete
action, the test-window start indices (numpy's legacy RandomState, the
reference's generator) and the mean angle error of the zero-velocity
predictor (every predicted frame = the last observed frame). The Rust tests in
crates/eval/src/cmu_dmgnn.rs compare their own figures with these.

    python3 -m venv /tmp/np && /tmp/np/bin/pip install numpy
    /tmp/np/bin/python benches/cmu_dmgnn_protocol_check.py [../shared/data/cmu_dmgnn]
"""
import math
import os
import sys

import numpy as np

ACTIONS = ["basketball", "jumping", "running", "soccer", "walking"]
SEED = 1234567890
OBSERVED, PREDICTED, WINDOWS = 50, 10, 8
EPS = float(np.finfo(np.float32).eps)


def read(path):
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line:
                rows.append([float(x) for x in line.split(",")])
    a = np.array(rows, dtype=np.float64)
    assert a.shape[1] == 117, path
    return a


def used_dims():
    # Whole triplets of the data (triplet 0 = root position, triplet t >= 1 =
    # joint t's exponential map): the 26 joints the reference predicts.
    triplets = [3, 4, 5, 6, 9, 10, 11, 12, 14, 15, 16, 17, 18, 19,
                22, 23, 24, 25, 26, 28, 31, 32, 33, 34, 35, 37]
    return [3 * t + k for t in triplets for k in range(3)]


def rotation(r):
    # Rodrigues' formula with the reference's epsilon in the axis
    # normalisation, all in float64 (a numpy float32 scalar here would turn
    # the axis into float32 under numpy 2's promotion rules).
    theta = math.sqrt(float(np.dot(r, r)))
    k = r / (theta + EPS)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(theta) * kx + (1.0 - math.cos(theta)) * kx @ kx


def euler(m):
    if m[0, 2] == 1.0 or m[0, 2] == -1.0:
        e3 = 0.0
        d = math.atan2(m[0, 1], m[0, 2])
        if m[0, 2] == -1.0:
            return np.array([e3 + d, math.pi / 2, e3])
        return np.array([-e3 + d, -math.pi / 2, e3])
    e2 = -math.asin(m[0, 2])
    c = math.cos(e2)
    return np.array([math.atan2(m[1, 2] / c, m[2, 2] / c), e2, math.atan2(m[0, 1] / c, m[0, 0] / c)])


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        os.path.dirname(__file__), "..", "..", "shared", "data", "cmu_dmgnn")
    # Statistics over every training frame (full rate) of the complete actions.
    train = []
    for a in ACTIONS:
        n = len(os.listdir(os.path.join(root, "train", a)))
        for i in range(1, n + 1):
            train.append(read(os.path.join(root, "train", a, f"{a}_{i}.txt")))
    allf = np.concatenate(train)
    mean, std = allf.mean(0), allf.std(0)
    constant = std < 1e-4
    std[constant] = 1.0
    use = used_dims()
    keep = np.zeros(117, dtype=bool)
    keep[use] = True
    keep &= ~constant

    def as_seen(frames):
        # What survives normalisation and un-normalisation: the used,
        # non-constant dims; everything else at the training mean.
        out = np.tile(mean, (frames.shape[0], 1))
        out[:, keep] = frames[:, keep]
        return out

    def to_euler(frames):
        e = np.zeros_like(frames)
        for j in range(frames.shape[0]):
            for t in range(39):
                e[j, 3 * t:3 * t + 3] = euler(rotation(frames[j, 3 * t:3 * t + 3]))
        return e

    print(f"zero-std training dims: {int(constant.sum())}; used dims: {len(use)}")
    table = {}
    for a in ACTIONS:
        raw = read(os.path.join(root, "test", a, f"{a}_1.txt"))
        even = raw[0::2]
        rng = np.random.RandomState(SEED)  # a new generator per action
        starts = [int(rng.randint(0, even.shape[0] - OBSERVED - PREDICTED)) for _ in range(WINDOWS)]
        errs = np.zeros((WINDOWS, PREDICTED))
        for w, s in enumerate(starts):
            obs = even[s:s + OBSERVED]
            tgt = even[s + OBSERVED:s + OBSERVED + PREDICTED]
            pred = np.tile(obs[-1], (PREDICTED, 1))
            te, pe = to_euler(as_seen(tgt)), to_euler(as_seen(pred))
            te[:, 0:6] = 0.0
            sel = (te.std(0) > 1e-4) & ~constant
            errs[w] = np.sqrt(((te[:, sel] - pe[:, sel]) ** 2).sum(1))
        mae = errs.mean(0)
        table[a] = mae
        print(f"{a}: lines {raw.shape[0]}, even frames {even.shape[0]}, starts {starts}")
        print(f"{a}: zero-velocity MAE per frame " + " ".join(f"{x:.9f}" for x in mae))
    print()
    print("| action | 40 ms | 240 ms | 400 ms |")
    print("|---|---|---|---|")
    for a in ACTIONS:
        m = table[a]
        print(f"| {a} | {m[0]:.3f} | {m[5]:.3f} | {m[9]:.3f} |")
    avg = np.mean([table[a] for a in ACTIONS], 0)
    print(f"| average | {avg[0]:.3f} | {avg[5]:.3f} | {avg[9]:.3f} |")


if __name__ == "__main__":
    main()
