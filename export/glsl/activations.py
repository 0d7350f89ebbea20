"""Elementwise activations as epilogue steps, shared by both targets (GLSL expression + numpy
reference)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from neuralao.export.glsl.graph import glsl_float
from neuralao.export.glsl.templates import fill


@dataclass
class Act:
    """An elementwise activation applied in a layer's epilogue. ``op`` is the ONNX op type."""

    op: str
    params: dict[str, float] = field(default_factory=dict)

    def expr(self, x: str, fill: Callable[..., str] = fill) -> str:
        """vec4 expression applying this activation to the vec4 expression ``x``; ``fill`` picks the
        language's templates (GLSL by default, ``Dialect.fill`` of the compute dialect)."""
        if self.op == "LeakyRelu":
            return fill("act_LeakyRelu", x=x, alpha=glsl_float(self.params["alpha"]))
        if self.op == "Clip":
            lo, hi = self.params.get("lo"), self.params.get("hi")
            if lo is not None and hi is not None:
                return fill("act_Clip", x=x, lo=glsl_float(lo), hi=glsl_float(hi))
            if lo is not None:
                return fill("act_Clip_min", x=x, lo=glsl_float(lo))
            if hi is not None:
                return fill("act_Clip_max", x=x, hi=glsl_float(hi))
            return fill("act_Identity", x=x)
        if self.op == "Elu":
            return fill("act_Elu", x=x, alpha=glsl_float(self.params["alpha"]))
        if self.op == "HardSigmoid":
            return fill(
                "act_HardSigmoid",
                x=x,
                alpha=glsl_float(self.params["alpha"]),
                beta=glsl_float(self.params["beta"]),
            )
        if self.op == "Pow":
            return _pow_expr(x, self.params["e"], fill)
        return fill(f"act_{self.op}", x=x)

    def numpy(self, x: np.ndarray) -> np.ndarray:
        """Reference semantics (float64), used only by tests and docs."""
        if self.op == "Relu":
            return np.maximum(x, 0)
        if self.op == "LeakyRelu":
            return np.where(x >= 0, x, self.params["alpha"] * x)
        if self.op == "Sigmoid":
            return 1 / (1 + np.exp(-x))
        if self.op == "Tanh":
            return np.tanh(x)
        if self.op == "Clip":
            return np.clip(x, self.params.get("lo", -np.inf), self.params.get("hi", np.inf))
        if self.op == "Sin":
            return np.sin(x)
        if self.op == "Cos":
            return np.cos(x)
        if self.op == "Elu":
            return np.where(x >= 0, x, self.params["alpha"] * np.expm1(np.minimum(x, 0)))
        if self.op == "Softplus":
            return np.maximum(x, 0) + np.log1p(np.exp(-np.abs(x)))
        if self.op == "HardSigmoid":
            return np.clip(self.params["alpha"] * x + self.params["beta"], 0, 1)
        return x


def clip_bounds(min_: np.ndarray | None, max_: np.ndarray | None) -> dict[str, float]:
    out: dict[str, float] = {}
    for key, v in (("lo", min_), ("hi", max_)):
        if v is not None:
            arr = np.asarray(v)
            if arr.size != 1:
                raise ValueError("Clip bounds must be scalars")
            out[key] = float(arr.reshape(()))
    return out


def _pow_expr(x: str, e: float, fill: Callable[..., str] = fill) -> str:
    """x ** e: products for small integer exponents (exact as onnxruntime's std::pow, and defined for
    negative x), sqrt for 0.5, else pow() (GLSL leaves it undefined for x < 0, where ONNX gives NaN)."""
    if e == int(e) and abs(e) <= 4:
        n = int(abs(e))
        product = fill("act_Pow_one") if n == 0 else fill("pow_product", factors=" * ".join([x] * n))
        return fill("act_Pow_reciprocal", x=product) if e < 0 else product
    if e == 0.5:
        return fill("act_Sqrt", x=x)
    return fill("act_Pow", x=x, e=glsl_float(e))
