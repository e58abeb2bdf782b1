#!/usr/bin/env python3
"""Train the deep motion model network (DMMN) and export it for infotrack.

One command from flight-log CSV to ONNX:

    python training/train_dmmn.py --data data/lab.csv --out models/

The CSV is infotrack's per-step log format (what `infotrack dataset` and the daemon's
flight logs write): rows with `measured == 1` give the noisy target positions
`z_x_enu_m, z_y_enu_m` at the filter rate; a gap (an unmeasured row or a time step that
is not one filter period) starts a new segment, and windows never cross segments.

The architecture is the paper's (Pulido et al.), as the authors' code builds it: a linear
embedding 2 -> d, a learned positional embedding (K_in x d), pre-norm blocks of causal
multi-head self-attention (no biases on q/k/v) and a ReLU feed-forward d -> ff -> d with
dropout, a final LayerNorm and a linear head on the last time step. Parameter names match
the authors' except that the attention heads share one fused q/k/v projection (same
function, a faster graph); their published weights load into it (`--load-original`).

What infotrack needs from the export: the ONNX graph takes `history` [batch, K_in, 2]
(world ENU metres, oldest first) and returns `next` [batch, 2], the absolute next position
in metres. Any normalisation is inside the graph; `dmmn.json` records how.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn



# ---------------------------------------------------------------------------- data


def load_segments(paths: list[Path], dt_s: float) -> tuple[list[np.ndarray], str]:
    """Contiguous runs of measured positions, and the sha256 of the files read."""
    h = hashlib.sha256()
    segments: list[np.ndarray] = []
    for path in paths:
        raw = path.read_bytes()
        h.update(raw)
        lines = raw.decode().splitlines()
        if raw and not raw.endswith(b"\n"):
            # A flight stopped mid-write leaves its last row cut short: leave it out.
            print(f"{path}: the last line is cut short (an interrupted flight); left out")
            lines = lines[:-1]
        rows = csv.DictReader(lines)
        need = {"t_s", "measured", "z_x_enu_m", "z_y_enu_m"}
        if rows.fieldnames is None or not need.issubset(rows.fieldnames):
            sys.exit(f"{path}: not an infotrack log CSV (needs columns {sorted(need)})")
        cur: list[tuple[float, float]] = []
        last_t = None
        for lineno, r in enumerate(rows, start=2):
            try:
                t = float(r["t_s"])
                measured = r["measured"].strip() == "1"
                if measured:
                    x, y = float(r["z_x_enu_m"]), float(r["z_y_enu_m"])
            except ValueError as e:
                sys.exit(f"{path}:{lineno}: {e}")
            contiguous = last_t is not None and abs(t - last_t - dt_s) < 0.25 * dt_s
            if not measured or (cur and not contiguous):
                if len(cur) > 1:
                    segments.append(np.asarray(cur))
                cur = []
            if measured:
                if not (math.isfinite(x) and math.isfinite(y)):
                    sys.exit(f"{path}:{lineno}: non-finite position")
                cur.append((x, y))
            last_t = t
        if len(cur) > 1:
            segments.append(np.asarray(cur))
    return segments, h.hexdigest()


def windows(segments: list[np.ndarray], k_in: int) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = [], []
    for s in segments:
        for i in range(len(s) - k_in):
            xs.append(s[i : i + k_in])
            ys.append(s[i + k_in])
    return np.asarray(xs, dtype=np.float32), np.asarray(ys, dtype=np.float32)


# ---------------------------------------------------------------------------- model


class MultiHead(nn.Module):
    """Causal multi-head self-attention with all heads in one q/k/v projection.

    The same function as the authors' per-head modules (their weights load into it, see
    `load_original`), with a few large operations instead of many small ones: the ONNX graph
    is several times faster to run.
    """

    def __init__(self, d: int, heads: int, head_size: int, k_in: int, dropout: float):
        super().__init__()
        self.heads, self.head_size = heads, head_size
        self.qkv = nn.Linear(d, 3 * heads * head_size, bias=False)
        self.proj = nn.Linear(heads * head_size, d)
        self.dropout = nn.Dropout(dropout)
        mask = torch.full((k_in, k_in), float("-inf")).triu(1)
        self.register_buffer("mask", mask)
        self.scale = head_size**-0.5

    def forward(self, x, last_only: bool = False):
        """Attention output for every position, or (last_only) for the last one only:
        [B, T, d] -> [B, T, d] or [B, 1, d]."""
        t = x.shape[1]
        hh, hs = self.heads, self.head_size
        q, k, v = self.qkv(x.reshape(-1, x.shape[-1])).reshape(-1, t, 3 * hh * hs).split(hh * hs, dim=-1)
        mask = self.mask
        if last_only:
            q = q[:, -1:, :]
            mask = mask[-1:, :]
        tq = q.shape[1]
        q = q.reshape(-1, tq, hh, hs).transpose(1, 2)
        k = k.reshape(-1, t, hh, hs).transpose(1, 2)
        v = v.reshape(-1, t, hh, hs).transpose(1, 2)
        if hs == 1:
            # Outer products as broadcast multiplies: far cheaper than thousands of 1-wide
            # batched matrix products in the exported graph.
            w = q * k.transpose(-2, -1)
        else:
            w = q @ k.transpose(-2, -1)
        if self.scale != 1.0:
            w = w * self.scale
        w = torch.softmax(w + mask, dim=-1)
        if hs == 1:
            y = (w * v.transpose(-2, -1)).sum(-1, keepdim=True)
        else:
            y = w @ v
        y = y.transpose(1, 2).reshape(-1, tq, hh * hs)
        return self.dropout(self.proj(y))


class FeedForward(nn.Module):
    def __init__(self, d: int, ff: int, dropout: float):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(d, ff), nn.ReLU(), nn.Linear(ff, d), nn.Dropout(dropout))

    def forward(self, x):
        # On 2-D rows, so that the exported MatMul + bias fuse into one Gemm.
        shape = x.shape
        return self.net(x.reshape(-1, shape[-1])).reshape(shape)


class Block(nn.Module):
    def __init__(self, d, heads, head_size, ff, k_in, dropout):
        super().__init__()
        self.sa = MultiHead(d, heads, head_size, k_in, dropout)
        self.ffwd = FeedForward(d, ff, dropout)
        self.ln1 = nn.LayerNorm(d)
        self.ln2 = nn.LayerNorm(d)

    def forward(self, x, last_only: bool = False):
        """last_only: only the last position's output ([B, 1, d]), which is all the head
        reads from the final block; the earlier positions still feed its attention."""
        a = self.sa(self.ln1(x), last_only)
        x = (x[:, -1:, :] if last_only else x) + a
        return x + self.ffwd(self.ln2(x))


class Dmmn(nn.Module):
    """Takes [B, K_in, 2] metres, returns [B, 2] absolute next position in metres."""

    def __init__(self, k_in, d, heads, head_size, ff, layers, dropout, input_norm, output, center, scale, step_scale):
        super().__init__()
        self.embed = nn.Linear(2, d)
        self.position_embedding_table = nn.Embedding(k_in, d)
        self.blocks = nn.Sequential(*[Block(d, heads, head_size, ff, k_in, dropout) for _ in range(layers)])
        self.ln_f = nn.LayerNorm(d)
        self.lm_head = nn.Linear(d, 2)
        self.input_norm = input_norm
        self.output = output
        self.register_buffer("center", torch.tensor(center, dtype=torch.float32))
        self.register_buffer("scale", torch.tensor(scale, dtype=torch.float32))
        self.register_buffer("step_scale", torch.tensor(step_scale, dtype=torch.float32))
        self.register_buffer("pos", torch.arange(k_in))

    def forward(self, x):
        last = x[:, -1:, :]
        if self.input_norm == "none":
            h = x
        elif self.input_norm == "workspace":
            h = (x - self.center) / self.scale
        elif self.input_norm == "last":
            h = (x - last) / self.step_scale
        else:
            raise ValueError(self.input_norm)
        h = self.embed(h) + self.position_embedding_table(self.pos)
        n = len(self.blocks)
        for i, block in enumerate(self.blocks):
            h = block(h, last_only=(i == n - 1))
        out = self.lm_head(self.ln_f(h[:, -1, :]))
        if self.output == "displacement":
            return last[:, 0, :] + out * self.step_scale
        if self.input_norm == "workspace":
            return out * self.scale + self.center
        return out


def load_original(model: Dmmn, path: Path):
    """Loads the authors' published weights (named tensors with shapes) into `model`: their
    per-head key/query/value matrices are stacked into the fused projection."""
    blob = json.loads(path.read_text())
    raw = {name: torch.tensor(np.asarray(t["data"], dtype=np.float32).reshape(t["shape"])) for name, t in blob.items()}
    state = {}
    layers = len(model.blocks)
    heads = model.blocks[0].sa.heads
    for name, t in raw.items():
        if ".sa.heads." not in name:
            state[name] = t
    for l in range(layers):
        parts = []
        for kind in ("query", "key", "value"):
            for h in range(heads):
                key = f"blocks.{l}.sa.heads.{h}.{kind}.weight"
                if key not in raw:
                    sys.exit(f"{path}: missing {key}")
                parts.append(raw[key])
        state[f"blocks.{l}.sa.qkv.weight"] = torch.cat(parts, dim=0)
    missing, unexpected = model.load_state_dict(state, strict=False)
    buffers = {"center", "scale", "step_scale", "pos"}
    missing = [m for m in missing if m not in buffers and not m.endswith(".mask")]
    if missing or unexpected:
        sys.exit(f"{path}: weights do not fit the architecture: missing {missing}, unexpected {unexpected}")


# ---------------------------------------------------------------------------- training


def rmse(model: Dmmn, x: torch.Tensor, y: torch.Tensor) -> float:
    model.eval()
    with torch.no_grad():
        return float(torch.sqrt(((model(x) - y) ** 2).sum(-1).mean()))


def cv_rmse(x: np.ndarray, y: np.ndarray, max_step: float) -> float:
    v = (x[:, -1] - x[:, 0]) / (x.shape[1] - 1)
    s = np.linalg.norm(v, axis=1, keepdims=True)
    v = np.where(s > max_step, v * max_step / np.maximum(s, 1e-12), v)
    return float(np.sqrt((((x[:, -1] + v) - y) ** 2).sum(-1).mean()))


def train(args, xtr, ytr, xva, yva, center, scale, step_scale, log=print):
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    model = Dmmn(
        args.k_in, args.width, args.heads, args.head_size, args.ff, args.layers, args.dropout,
        args.input_norm, args.output, center, scale, step_scale,
    )
    xtr_t, ytr_t = torch.from_numpy(xtr), torch.from_numpy(ytr)
    xva_t, yva_t = torch.from_numpy(xva), torch.from_numpy(yva)
    opt = torch.optim.Adam(model.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=args.epochs)
    n = len(xtr)
    best = (float("inf"), None)
    for epoch in range(args.epochs):
        model.train()
        perm = torch.randperm(n)
        for i in range(0, n, args.batch):
            idx = perm[i : i + args.batch]
            loss = ((model(xtr_t[idx]) - ytr_t[idx]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        sched.step()
        if epoch % 10 == 9 or epoch == args.epochs - 1:
            v = rmse(model, xva_t, yva_t)
            if v < best[0]:
                best = (v, {k: t.clone() for k, t in model.state_dict().items()})
            if epoch % 100 == 99:
                log(f"  epoch {epoch + 1}: val RMSE {v:.4f} m (best {best[0]:.4f})")
    model.load_state_dict(best[1])
    model.eval()
    return model, best[0]


def export(model: Dmmn, out_dir: Path, k_in: int, xva: np.ndarray):
    from fast_graph import export_batch_last

    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "dmmn.onnx"
    # The same function computed batch-last: several times faster in ONNX Runtime (see
    # fast_graph.py); the parity fixture below is the batch-first PyTorch model's output.
    export_batch_last(model, path, xva[:4])
    # The parity fixture: inputs and PyTorch outputs that the Rust runtime must reproduce.
    rng = np.random.default_rng(0)
    pick = rng.choice(len(xva), size=min(64, len(xva)), replace=False)
    xs = xva[pick]
    with torch.no_grad():
        ys = model(torch.from_numpy(xs)).numpy()
    (out_dir / "dmmn_parity.json").write_text(
        json.dumps({"k_in": k_in, "inputs": xs.reshape(len(xs), -1).tolist(), "outputs": ys.tolist()})
    )
    return path


def load_world(data, world_file):
    """The world the model is trained for: infotrack refuses the model in any other. Every data
    file must come from the same world (road graph, workspace, target speeds, K_in, dt)."""
    files = [world_file] if world_file else [d.with_suffix(".world.json") for d in data]
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        sys.exit(f"no world file {', '.join(missing)}: record the data with `infotrack dataset` "
                 f"(it writes one), or write it with `infotrack dataset --config YOUR.toml "
                 f"--world-only --out DATA.csv` and pass --world")
    worlds = [json.loads(f.read_text()) for f in files]
    named = {k: v for k, v in worlds[0].items() if k != "name"}
    for f, w in zip(files[1:], worlds[1:]):
        if {k: v for k, v in w.items() if k != "name"} != named:
            sys.exit(f"{f} is another world than {files[0]}: train one model per world")
    return worlds[0]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, nargs="+", required=True, help="infotrack log CSV file(s)")
    p.add_argument("--out", type=Path, default=Path("models"), help="output directory")
    p.add_argument("--recipe", default="", help="how the data was made, recorded in dmmn.json")
    p.add_argument("--dt", type=float, default=1 / 3, help="filter period of the data, s")
    p.add_argument("--k-in", type=int, default=10)
    p.add_argument("--width", type=int, default=5)
    p.add_argument("--heads", type=int, default=4)
    p.add_argument("--head-size", type=int, default=1)
    p.add_argument("--ff", type=int, default=50)
    p.add_argument("--layers", type=int, default=2)
    p.add_argument("--dropout", type=float, default=0.2)
    p.add_argument("--input-norm", choices=["none", "workspace", "last"], default="none")
    p.add_argument("--output", choices=["absolute", "displacement"], default="absolute")
    p.add_argument("--epochs", type=int, default=300)
    p.add_argument("--batch", type=int, default=256)
    p.add_argument("--lr", type=float, default=3e-3)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--cv-max-speed", type=float, default=0.7, help="for the constant-velocity baseline RMSE, m/s")
    p.add_argument("--load-original", type=Path, help="evaluate the authors' weights instead of training")
    p.add_argument("--no-export", action="store_true")
    p.add_argument("--world", type=Path,
                   help="the world the data comes from (infotrack dataset --world-only writes it); "
                        "default: the <data>.world.json that infotrack dataset wrote beside each file")
    args = p.parse_args()
    world = load_world(args.data, args.world)
    torch.set_num_threads(1)

    segments, sha = load_segments(args.data, args.dt)
    x, y = windows(segments, args.k_in)
    if len(x) < 100:
        sys.exit(f"only {len(x)} training windows in {args.data}; record more data")
    split = int(0.8 * len(x))
    xtr, ytr, xva, yva = x[:split], y[:split], x[split:], y[split:]
    pts = np.concatenate(segments)
    center = ((pts.min(0) + pts.max(0)) / 2).tolist()
    scale = float(max(pts.max(0) - pts.min(0)) / 2)
    step_scale = float(np.median(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    baseline = cv_rmse(xva, yva, args.cv_max_speed * args.dt)
    print(f"{len(segments)} segments, {len(x)} windows ({split} train / {len(x) - split} validation); "
          f"constant-velocity one-step RMSE on validation {baseline:.4f} m")

    started = time.time()
    if args.load_original:
        args.input_norm, args.output = "none", "absolute"
        args.width, args.heads, args.head_size, args.ff, args.layers = 5, 4, 1, 50, 2
        model = Dmmn(args.k_in, 5, 4, 1, 50, 2, 0.0, "none", "absolute", center, scale, step_scale)
        load_original(model, args.load_original)
        model.eval()
        val = rmse(model, torch.from_numpy(xva), torch.from_numpy(yva))
    else:
        model, val = train(args, xtr, ytr, xva, yva, center, scale, step_scale)
    params = sum(t.numel() for t in model.parameters())
    print(f"validation one-step RMSE {val:.4f} m, {params} parameters, {time.time() - started:.0f} s")
    if args.no_export:
        return
    path = export(model, args.out, args.k_in, xva)
    meta = {
        "format": "infotrack-dmmn/1",
        "k_in": args.k_in,
        "dt_s": args.dt,
        "input": {"name": "history", "shape": ["batch", args.k_in, 2], "units": "m", "frame": "world ENU", "order": "oldest first"},
        "output": {"name": "next", "shape": ["batch", 2], "units": "m", "frame": "world ENU", "meaning": "absolute next position"},
        "input_normalisation": args.input_norm,
        "output_convention": args.output,
        "normalisation_constants": {"center_m": center, "scale_m": scale, "step_scale_m": step_scale},
        "architecture": {"width": args.width, "heads": args.heads, "head_size": args.head_size, "ff": args.ff,
                         "layers": args.layers, "dropout": args.dropout},
        "parameters": params,
        "training": {"files": [str(d) for d in args.data], "sha256": sha, "recipe": args.recipe,
                     "windows_train": split, "windows_validation": len(x) - split, "epochs": args.epochs,
                     "batch": args.batch, "lr": args.lr, "seed": args.seed, "torch": torch.__version__,
                     "original_weights": str(args.load_original) if args.load_original else None},
        "validation": {"one_step_rmse_m": val, "cv_baseline_one_step_rmse_m": baseline},
        "world": world,
    }
    (args.out / "dmmn.json").write_text(json.dumps(meta, indent=2) + "\n")
    print(f"wrote {path}, {args.out / 'dmmn.json'} and {args.out / 'dmmn_parity.json'}")


if __name__ == "__main__":
    main()
