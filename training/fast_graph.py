#!/usr/bin/env python3
"""The DMMN's fast ONNX graph: the same function as `Dmmn`, computed batch-last.

Why: the model is tiny (width 5, 4 heads of size 1, 10 time steps) and a batch is large
(500-5,000 particles). Exported as PyTorch writes it, batch-first, every element-wise op,
LayerNorm and softmax in the graph runs over inner dimensions of 2-10 elements, and ONNX
Runtime spends its time in per-row loops instead of arithmetic (3.2 ms per batch
of 500 where the arithmetic needs ~0.15 ms). Here every tensor keeps the batch as its last,
contiguous axis: positions are `[d, K, B]`, attention weights `[heads, K, K, B]`, linear
layers are one GEMM over `[d, K*B]`, LayerNorm and softmax reduce over a leading axis. The
graph's interface is unchanged: `history` [batch, K_in, 2] in, `next` [batch, 2] out; the
first GEMM (input normalisation, embedding and positions as one affine map) reads the
batch-first input and the head's GEMM writes batch-first output, so there is no transpose.
Fewer nodes matter as much as layout (each costs ~1-3 us of dispatch at this size): LayerNorm's
eps is a GEMM bias, softmax's max subtraction is dropped when the weights bound the logits
(`logit_bound`), its normalisation multiplies the weighted sum rather than the weights, and a
causal mask's all-zero last row is not added.

    python training/fast_graph.py models/dmmn.onnx        # rewrite a shipped model in place

reads the weights from an exported model (either layout), rebuilds the graph batch-last,
checks it against the model's PyTorch parity fixture (`dmmn_parity.json`, <= 1e-5) and
against the old graph in ONNX Runtime, and writes it over the old one. `train_dmmn.py`
exports this layout directly.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch
from torch import nn

# train_dmmn.py sits beside this file.
sys.path.insert(0, str(Path(__file__).resolve().parent))
from train_dmmn import Dmmn  # noqa: E402


def folded_linear(ln: nn.LayerNorm, lin: nn.Linear) -> tuple[torch.Tensor, torch.Tensor]:
    """The weight and bias of `lin(ln(.))` with LayerNorm's gain and shift folded in:
    W (g * n + beta) + b = (W diag g) n + (W beta + b). Returns ([out, in], [out, 1])."""
    w = lin.weight * ln.weight[None, :]
    b = lin.weight @ ln.bias
    if lin.bias is not None:
        b = b + lin.bias
    return w.detach().clone(), b.detach().clone()[:, None]


def plain_linear(lin: nn.Linear) -> tuple[torch.Tensor, torch.Tensor]:
    """([out, in], [out, 1]) of `lin`."""
    return lin.weight.detach().clone(), lin.bias.detach().clone()[:, None]


# exp(60) = 1.1e26: ten of them sum far below float32's 3.4e38, and exp(-60) = 8.8e-27 is a
# normal float32. Within +-60 the softmax needs no max subtraction.
SAFE_LOGIT = 60.0


def logit_bound(blk) -> float:
    """An upper bound on |q . k| * scale in block `blk`'s attention, from its weights alone.
    LayerNorm's output n (before gain and shift) has |n| <= sqrt(d); with the gain and shift
    folded in, each q or k coordinate is w . n + b, so |q_c| <= |w|_2 sqrt(d) + |b|, and a
    head's logit is bounded by the product of its q and k bounds."""
    w, b = folded_linear(blk.ln1, blk.sa.qkv)
    d = w.shape[1]
    coord = (w.norm(dim=1) * d ** 0.5 + b[:, 0].abs()).reshape(3, blk.sa.heads, blk.sa.head_size)
    q, k = coord[0], coord[1]
    return float(((q * k).sum(1)).max() * abs(float(blk.sa.scale)))


def embedding_affine(m: Dmmn) -> tuple[torch.Tensor, torch.Tensor]:
    """`m`'s input normalisation, embedding and learned positions as one affine map of the
    flattened history: [K*2] -> [d*K] rows ordered (feature, time step), so that the result
    reshapes to [d, K, B] for free. Every step of it is affine in the input (the "last"
    normalisation subtracts a linear function of the input too), so the map is read off
    exactly by evaluating it at 0 and at the unit vectors, in float64. Returns (A [d*K, K*2],
    c [d*K, 1])."""
    k, d = int(m.pos.numel()), int(m.embed.weight.shape[0])
    w = m.embed.weight.detach().double()
    table = (m.embed.bias[:, None] + m.position_embedding_table.weight.t()).detach().double()  # [d, K]
    # Per-axis ([2]) or one number: either broadcasts over [K, 2] as a row.
    center, scale, step = (t.detach().double().reshape(1, -1) for t in (m.center, m.scale, m.step_scale))

    def f(x):  # [K, 2] -> [d*K]
        if m.input_norm == "none":
            h = x
        elif m.input_norm == "workspace":
            h = (x - center) / scale
        elif m.input_norm == "last":
            h = (x - x[k - 1 : k, :]) / step
        else:
            raise ValueError(m.input_norm)
        return ((w @ h.t()) + table).reshape(-1)  # [d, K] -> (feature, step) order

    base = f(torch.zeros(k, 2, dtype=torch.float64))
    cols = [f(torch.eye(2 * k, dtype=torch.float64)[j].reshape(k, 2)) - base for j in range(2 * k)]
    return torch.stack(cols, 1).float(), base.float()[:, None]


class DmmnBatchLast(nn.Module):
    """`Dmmn`'s forward pass with the batch as the last axis of every tensor, for inference.
    Built from a trained model (eval mode: no dropout); its weights are copied once, with
    each LayerNorm's gain and shift folded into the linear layer after it. Every shape but
    the batch is a Python constant and the batch is always `-1`, so the exported graph has
    no shape arithmetic and no constant subgraphs."""

    def __init__(self, model: Dmmn):
        super().__init__()
        m = model
        self.k = int(m.pos.numel())
        self.d = int(m.embed.weight.shape[0])
        self.input_norm, self.output = m.input_norm, m.output
        self.blocks_n = len(m.blocks)
        self.heads = [blk.sa.heads for blk in m.blocks]
        self.head_size = [blk.sa.head_size for blk in m.blocks]
        self.scales = [float(blk.sa.scale) for blk in m.blocks]
        self.eps = [(float(blk.ln1.eps), float(blk.ln2.eps)) for blk in m.blocks] + [float(m.ln_f.eps)]
        d, k = self.d, self.k
        buf = self.register_buffer
        buf("center", m.center.detach().clone().reshape(2, 1, 1))
        buf("scale", m.scale.detach().clone())
        buf("step_scale", m.step_scale.detach().clone())
        # Input normalisation, embedding and positions are one affine map of the flattened
        # history [K*2] -> [d*K]: one Gemm reads the batch-first input and writes batch-last.
        a, c = embedding_affine(m)
        buf("embed_a", a)
        buf("embed_c", c)
        # LayerNorm's mean and variance over the d features as matrix products: ONNX Runtime
        # runs them as GEMMs over the long axis instead of reductions over a short one.
        buf("centring", torch.eye(d) - torch.full((d, d), 1.0 / d))
        buf("mean_row", torch.full((1, d), 1.0 / d))
        for i, blk in enumerate(m.blocks):
            for name, (w, b) in (
                ("qkv", folded_linear(blk.ln1, blk.sa.qkv)),
                ("proj", plain_linear(blk.sa.proj)),
                ("ff1", folded_linear(blk.ln2, blk.ffwd.net[0])),
                ("ff2", plain_linear(blk.ffwd.net[2])),
            ):
                buf(f"b{i}_{name}_w", w)
                buf(f"b{i}_{name}_b", b)
            buf(f"b{i}_mask", blk.sa.mask.detach().clone())
        self.safe_logits = [logit_bound(blk) < SAFE_LOGIT for blk in m.blocks]
        self.last_row_masked = [bool((blk.sa.mask[-1] != 0).any()) for blk in m.blocks]
        hw, hb = folded_linear(m.ln_f, m.lm_head)
        buf("head_w", hw)
        buf("head_b", hb)

    def linear(self, name: str, h: torch.Tensor) -> torch.Tensor:
        """The stored linear layer `name` on every column of [in, N]: one Gemm, [out, N]."""
        return torch.addmm(getattr(self, name + "_b"), getattr(self, name + "_w"), h)

    def normalize(self, h: torch.Tensor, eps: float) -> torch.Tensor:
        """LayerNorm's normalisation (gain and shift are folded into the next layer) over
        axis 0 of [d, N], the features."""
        c = self.centring @ h
        # eps as the Gemm's bias; one reciprocal per column and a multiply (a divide over
        # [d, N] costs more, and Pow(-0.5) more than Sqrt and Reciprocal).
        var_eps = torch.addmm(self.eps_bias(eps), self.mean_row, c * c)
        return c * torch.reciprocal(torch.sqrt(var_eps))

    def eps_bias(self, eps: float) -> torch.Tensor:
        """eps as a [1, 1] tensor (a Gemm bias)."""
        return torch.full((1, 1), eps)

    def attention(self, i: int, h: torch.Tensor, last_only: bool) -> torch.Tensor:
        """Block i's attention on its LayerNorm of h: [d, K*B] -> [d, Kq*B] (Kq = 1 when
        last_only)."""
        k = self.k
        hh, hs = self.heads[i], self.head_size[i]
        qkv = self.linear(f"b{i}_qkv", self.normalize(h, self.eps[i][0]))
        q, kk, v = qkv.reshape(3, hh, hs, k, -1).split(1, dim=0)
        mask = getattr(self, f"b{i}_mask")
        kq = k
        if last_only:
            q = q.reshape(hh, hs, k, -1)[:, :, k - 1 :, :]
            mask = mask[k - 1 :, :]
            kq = 1
        if hs == 1:
            w = q.reshape(hh, kq, 1, -1) * kk.reshape(hh, 1, k, -1)  # [H, Kq, K, B]
        else:
            w = (q.reshape(hh, hs, kq, 1, -1) * kk.reshape(hh, hs, 1, k, -1)).sum(1)
        if self.scales[i] != 1.0:
            w = w * self.scales[i]
        if not last_only or self.last_row_masked[i]:  # a causal mask's last row is all zeros
            w = w + mask.reshape(1, kq, k, 1)
        # Softmax over the keys (axis 2), written out: ONNX Runtime's Softmax on a
        # non-last axis transposes the whole tensor twice. The usual max subtraction only
        # guards exp against overflow; it is left out when the weights bound every logit
        # well inside float32's range (see logit_bound).
        e = torch.exp(w if self.safe_logits[i] else w - w.amax(2, keepdim=True))
        # sum_j e_j v_j / sum_j e_j: the normalising multiply runs on the [H, Kq, B] result,
        # not on the [H, Kq, K, B] weights.
        inv = torch.reciprocal(e.sum(2))
        if hs == 1:
            y = (e * v.reshape(hh, 1, k, -1)).sum(2) * inv  # [H, Kq, B]
        else:
            y = (e.reshape(hh, 1, kq, k, -1) * v.reshape(hh, hs, 1, k, -1)).sum(3) * inv.reshape(hh, 1, kq, -1)
        return self.linear(f"b{i}_proj", y.reshape(hh * hs, -1))

    def block(self, i: int, h: torch.Tensor, last_only: bool) -> torch.Tensor:
        """Block i (pre-norm attention, then pre-norm feed-forward): [d, K*B] -> [d, Kq*B]."""
        d, k = self.d, self.k
        a = self.attention(i, h, last_only)
        x = (h.reshape(d, k, -1)[:, k - 1, :] if last_only else h) + a
        f = self.linear(f"b{i}_ff1", self.normalize(x, self.eps[i][1]))
        return x + self.linear(f"b{i}_ff2", torch.relu(f))

    def forward(self, x):
        d, k = self.d, self.k
        # [d*K, B] = A [d*K, K*2] . x^T + c: the transpose is the Gemm's transB.
        h = torch.addmm(self.embed_c, self.embed_a, x.reshape(-1, 2 * k).t()).reshape(d, -1)
        for i in range(self.blocks_n):
            h = self.block(i, h, last_only=(i == self.blocks_n - 1))
        n = self.normalize(h, self.eps[-1])  # [d, B]
        # The head writes batch-first [B, 2] (transA), so no transpose at the end either.
        out = torch.addmm(self.head_b.t(), n.t(), self.head_w.t())
        if self.output == "displacement":
            out = x[:, k - 1, :] + out * self.step_scale
        elif self.input_norm == "workspace":
            out = out * self.scale + self.center.reshape(1, 2)
        return out


def export_batch_last(model: Dmmn, path: Path, example: np.ndarray) -> None:
    """Writes `model` as the batch-last ONNX graph (`history` [batch, K_in, 2] -> `next`)."""
    model.eval()
    fast = DmmnBatchLast(model).eval()
    with torch.no_grad():
        torch.onnx.export(
            fast,
            (torch.from_numpy(example),),
            str(path),
            input_names=["history"],
            output_names=["next"],
            dynamic_axes={"history": {0: "batch"}, "next": {0: "batch"}},
            opset_version=17,
            dynamo=False,
        )


# ----------------------------------------------------------------- weights from an exported model


def model_from_onnx(path: Path, meta: dict) -> Dmmn:
    """A `Dmmn` with the weights of an exported graph. The named initializers load by name;
    PyTorch's exporter renames the transposed MatMul weights (`onnx::MatMul_N`) and the folded
    position table, and keeps them in the order the forward pass uses them: embed, then per
    block qkv and proj, then (last block) the last row of the mask."""
    import onnx
    from onnx import numpy_helper

    g = onnx.load(str(path)).graph
    inits = {i.name: numpy_helper.to_array(i) for i in g.initializer}
    renamed = sorted((n for n in inits if n.startswith("onnx::")), key=lambda n: int(n.rsplit("_", 1)[-1]))
    a = meta["architecture"]
    nc = meta["normalisation_constants"]
    k_in = meta["k_in"]
    model = Dmmn(k_in, a["width"], a["heads"], a["head_size"], a["ff"], a["layers"], 0.0,
                 meta["input_normalisation"], meta["output_convention"], nc["center_m"], nc["scale_m"],
                 nc["step_scale_m"])
    state = model.state_dict()
    loaded = {}
    for name, t in inits.items():
        key = name[2:] if name.startswith("m.") else name
        if key in state and tuple(state[key].shape) == t.shape:
            loaded[key] = torch.from_numpy(t.copy())
    if renamed:
        mats = [inits[n] for n in renamed]
        d, layers, hh, hs = a["width"], a["layers"], a["heads"], a["head_size"]
        want = [("embed.weight", (2, d), True), ("position_embedding_table.weight", (k_in, d), False)]
        for l in range(layers):
            want.append((f"blocks.{l}.sa.qkv.weight", (d, 3 * hh * hs), True))
            if l == layers - 1:
                want.append(("<last mask row>", (1, k_in), False))
            want.append((f"blocks.{l}.sa.proj.weight", (hh * hs, d), True))
        if len(mats) != len(want):
            sys.exit(f"{path}: {len(mats)} renamed initializers, expected {len(want)}: not a graph this script knows")
        for t, (key, shape, transposed) in zip(mats, want):
            if t.shape != shape:
                sys.exit(f"{path}: initializer for {key} has shape {t.shape}, expected {shape}")
            if key.startswith("<"):
                continue
            loaded[key] = torch.from_numpy((t.T if transposed else t).copy())
    missing = [k for k in state if k not in loaded and k not in ("pos",) and not k.endswith(".mask")
               and k not in ("center", "scale", "step_scale")]
    if missing:
        sys.exit(f"{path}: no weights found for {missing}")
    model.load_state_dict(loaded, strict=False)
    model.eval()
    return model


def excess(got: np.ndarray, want: np.ndarray, inputs: np.ndarray) -> float:
    """How far `got` misses `want` beyond the parity tolerance: 1e-5 m, or two float32
    roundings of the largest coordinate the model reads (a world 1 km across has an ulp of
    6e-5 m there, and the same operations in another order move the last bits). 0 when
    within."""
    tol = 1e-5 + 2 * float(np.spacing(np.float32(np.abs(inputs).max())))
    return float(np.max(np.maximum(np.abs(got.astype(np.float64) - want) - tol, 0.0)))


def is_batch_last(path: Path) -> bool:
    """This module's export names its folded weights `b<i>_qkv_w`, ..."""
    import onnx

    return any(i.name == "b0_qkv_w" for i in onnx.load(str(path)).graph.initializer)


def ort_session(path: Path):
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", type=Path, help="an exported dmmn.onnx (dmmn.json and dmmn_parity.json beside it)")
    p.add_argument("--out", type=Path, help="where to write the fast graph (default: over the model)")
    args = p.parse_args()
    torch.set_num_threads(1)
    meta = json.loads(args.model.with_suffix(".json").read_text())
    parity = json.loads((args.model.parent / "dmmn_parity.json").read_text())
    k_in = meta["k_in"]
    xs = np.asarray(parity["inputs"], dtype=np.float32).reshape(-1, k_in, 2)
    ys = np.asarray(parity["outputs"], dtype=np.float32)

    if is_batch_last(args.model):
        print(f"{args.model} is already the batch-last graph; nothing to do")
        return
    model = model_from_onnx(args.model, meta)
    with torch.no_grad():
        slow = model(torch.from_numpy(xs)).numpy()
        fast = DmmnBatchLast(model)(torch.from_numpy(xs)).numpy()
    err_weights = excess(slow, ys, xs)
    err_layout = excess(fast, ys, xs)
    print(f"weights read back: max |out - parity fixture| {np.abs(slow - ys).max():.2e} m (batch-first), "
          f"{np.abs(fast - ys).max():.2e} m (batch-last)")
    if err_weights > 0 or err_layout > 0:
        sys.exit("the rebuilt model does not reproduce the parity fixture; nothing written")

    out = args.out or args.model
    tmp = out.with_suffix(".fast.onnx")
    export_batch_last(model, tmp, xs[:4])
    old, new = ort_session(args.model), ort_session(tmp)
    rng = np.random.default_rng(1)
    batch = xs[rng.integers(0, len(xs), 500)] + rng.normal(0, 0.05, (500, k_in, 2)).astype(np.float32)
    a = old.run(None, {"history": batch})[0]
    b = new.run(None, {"history": batch})[0]
    c = new.run(None, {"history": xs})[0]
    print(f"ONNX Runtime: old vs new graph max diff {np.abs(a - b).max():.2e} m on 500 histories; "
          f"new vs parity fixture {np.abs(c - ys).max():.2e} m")
    print(f"beyond tolerance: {excess(b, a, batch):.2e} m (old vs new), {excess(c, ys, xs):.2e} m (fixture); worst at |y| = {np.abs(a).flat[np.argmax(np.abs(a - b))]:.1f} m")
    if excess(b, a, batch) > 0 or excess(c, ys, xs) > 0:
        tmp.unlink()
        sys.exit("the fast graph differs from the old one; nothing written")
    tmp.replace(out)
    import onnx

    print(f"wrote {out}: {len(onnx.load(str(out)).graph.node)} nodes")


if __name__ == "__main__":
    main()
