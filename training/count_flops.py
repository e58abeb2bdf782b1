#!/usr/bin/env python3
"""Counts the floating-point operations of one DMMN inference (the model's cost
as a fraction of what the core can do).

Walks the exported ONNX graph with shapes inferred for a given batch and counts, per node:
MatMul/Gemm 2*M*N*K (a multiply and an add per term), element-wise arithmetic one per
output element, reductions one per input element, Softmax 3 per element (exp, sum,
divide; the max subtraction counted as one more), LayerNormalization 8 per element (mean,
variance, normalise, scale, shift), Erf/Tanh/Sigmoid/Exp/Sqrt one per element (a transcendental
counts as one here: the ops are too small for their cost to matter next to the overhead).
Shape-only nodes (Reshape, Transpose, Gather, Concat, ...) count zero.

Usage: python training/count_flops.py models/dmmn.onnx [--batch 500]
"""
import argparse
from math import prod

import onnx
from onnx import shape_inference

ELEMENTWISE = {"Add", "Sub", "Mul", "Div", "Pow", "Relu", "Neg", "Abs", "Max", "Min", "Where",
               "Erf", "Tanh", "Sigmoid", "Exp", "Sqrt", "Reciprocal", "Log", "Clip"}
REDUCE = {"ReduceMean", "ReduceSum", "ReduceMax", "ReduceMin", "ReduceL2"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("model")
    ap.add_argument("--batch", type=int, default=500)
    a = ap.parse_args()
    m = onnx.load(a.model)
    for inp in list(m.graph.input) + list(m.graph.output):
        dims = inp.type.tensor_type.shape.dim
        if dims and not dims[0].HasField("dim_value"):
            dims[0].ClearField("dim_param")
            dims[0].dim_value = a.batch
    m = shape_inference.infer_shapes(m, data_prop=True)
    shapes = {}
    for v in list(m.graph.value_info) + list(m.graph.input) + list(m.graph.output):
        dims = v.type.tensor_type.shape.dim
        if all(d.HasField("dim_value") for d in dims):
            shapes[v.name] = [d.dim_value for d in dims]
    for init in m.graph.initializer:
        shapes[init.name] = list(init.dims)
    total, by_op, unknown = 0, {}, set()
    for n in m.graph.node:
        out = shapes.get(n.output[0]) if n.output else None
        ins = [shapes.get(i) for i in n.input]
        f = 0
        if n.op_type in ("MatMul", "Gemm"):
            if ins[0] is None or ins[1] is None or out is None:
                unknown.add(n.op_type)
                continue
            k = ins[0][-1]
            f = 2 * prod(out) * k
            if n.op_type == "Gemm" and len(n.input) > 2:
                f += prod(out)
        elif n.op_type in ELEMENTWISE:
            f = prod(out) if out else 0
            if out is None:
                unknown.add(n.op_type)
        elif n.op_type in REDUCE:
            f = prod(ins[0]) if ins[0] else 0
        elif n.op_type == "Softmax":
            f = 4 * prod(out) if out else 0
        elif n.op_type == "LayerNormalization":
            f = 8 * prod(out) if out else 0
        by_op[n.op_type] = by_op.get(n.op_type, 0) + f
        total += f
    print(f"model {a.model}, batch {a.batch}: {len(m.graph.node)} nodes, {total:,} FLOP "
          f"({total / a.batch:,.0f} per sequence)")
    for op, f in sorted(by_op.items(), key=lambda kv: -kv[1]):
        if f:
            print(f"  {op:<20} {f:>14,} FLOP  {100 * f / total:5.1f} %")
    if unknown:
        print(f"  (shapes not inferred for some {sorted(unknown)} nodes: not counted)")


if __name__ == "__main__":
    main()
