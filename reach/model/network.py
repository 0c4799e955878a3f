"""SIREN feedback networks (eq. 29 of the Taylor-ADS paper), loaded from plain ``.npz`` arrays.

A network of ``L`` layers maps the feedback states ``s`` to the outputs ``y``::

    x_1 = (s - input_offset) / input_scale                  (inputs scaled to [-1, 1])
    x_{i+1} = sin(omega (W_i x_i + b_i)),   i = 1 .. L-1     (eq. 29, the sine layers)
    y = W_L x_L + b_L                                        (linear output layer)

The file holds ``W1..WL``, ``b1..bL``, ``omega`` (a scalar) and ``input_offset``/``input_scale``
(one entry per input); it is read with ``allow_pickle=False``. The input scaling and ``omega``
are folded into the affine maps once, so each layer is one ``A x + c`` followed by ``sin``.

The same forward pass runs on floats, on numpy arrays (each input of shape ``(N,)``: a batch of
states, as the vectorised simulator passes them; each layer is a matrix-vector product per state,
so a state's outputs are bit for bit those it has alone, whatever the batch, which a matrix-matrix
product in BLAS does not guarantee) and on differential-algebra numbers: an input
with an ``affine`` method is a DA, and the layers become ``stack -> affine -> sin -> ...
-> unstack`` on the DA's own type, so this module does not depend on any back-end.

For the model, each output is a sympy implemented function (``siren_<tag>_k(s...)``) whose
``_imp_`` (a :class:`SirenOutput`) calls the network; ``sympy.lambdify`` and the Taylor back-end's
expression compiler both call ``_imp_``. One evaluation serves all outputs: the outputs of the last
call are kept and reused while the arguments are the same objects (and, for arrays, unchanged).
Networks, their outputs and so the models that use them pickle (the arrays, not the cache), so
such models can be sent to worker processes.
"""

from __future__ import annotations

import hashlib
import io
import re
import zipfile
from pathlib import Path

import numpy as np
import sympy
from sympy.core.function import UndefinedFunction

from reach.errors import InputError, Where
from reach.paths import read_bytes, within

#: the largest network weights file, packed and unpacked (a SIREN of 256 x 256 layers is 0.5 MB)
MAX_NETWORK_BYTES = 50_000_000


class Siren:
    """A loaded SIREN network: ``n_inputs`` feedback states -> ``n_outputs`` outputs."""

    def __init__(self, weights: list[np.ndarray], biases: list[np.ndarray], omega: float,
                 input_offset: np.ndarray, input_scale: np.ndarray, tag: str = "net"):
        self.weights, self.biases = weights, biases
        self.omega = float(omega)
        self.input_offset, self.input_scale = input_offset, input_scale
        self.tag = tag
        self.n_inputs, self.n_outputs = weights[0].shape[1], weights[-1].shape[0]
        layers = []
        for i, (W, b) in enumerate(zip(weights, biases)):
            if i == 0:          # x_1 = (s - offset)/scale folded into the first layer
                W, b = W / input_scale, b - W @ (input_offset / input_scale)
            gain = self.omega if i < len(weights) - 1 else 1.0
            layers.append((gain * W, gain * b))
        self._hidden, self._output = layers[:-1], layers[-1]
        self._last = None
        self._functions = None

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_last"] = state["_functions"] = None
        return state

    # ------------------------------------------------------------ loading
    @classmethod
    def load(cls, path, where: Where) -> "Siren":
        """Read and validate ``path``; every problem is one :class:`InputError` line naming the
        file and the array."""
        path = Path(path)
        label = path.name

        def fail(message):
            return where.error(f"{label}: {message}")

        try:
            found = path.is_file()
        except (OSError, ValueError):          # a name too long for the file system
            found = False
        if not found:
            raise fail("network weights file not found")
        home = Path(where.file).resolve().parent if where.file else Path.cwd()
        if not within(path, [home, Path.cwd()]):
            raise fail("lies outside the folder of the model file and the working folder: network "
                       "weights are read only from there")
        try:
            raw = read_bytes(path, (".npz",), "network weights file", MAX_NETWORK_BYTES)
        except InputError as exc:
            raise fail(exc.message) from None
        try:
            with zipfile.ZipFile(io.BytesIO(raw)) as archive:
                unpacked = sum(info.file_size for info in archive.infolist())
            if unpacked > MAX_NETWORK_BYTES:
                raise fail(f"its arrays take {unpacked} bytes unpacked, more than {MAX_NETWORK_BYTES}")
            with np.load(io.BytesIO(raw), allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            raise fail(f"not a readable .npz of plain arrays ({str(exc).splitlines()[0]})") from None
        count = 0
        while f"W{count + 1}" in arrays:
            count += 1
        if count == 0:
            raise fail("array 'W1' is missing")
        for name in [f"b{i}" for i in range(1, count + 1)] + ["omega", "input_offset", "input_scale"]:
            if name not in arrays:
                raise fail(f"array '{name}' is missing")
        extra = sorted(set(arrays) - {f"{p}{i}" for p in "Wb" for i in range(1, count + 1)}
                       - {"omega", "input_offset", "input_scale"})
        if extra:
            raise fail(f"unexpected array '{extra[0]}' (layers must be numbered W1..W{count} without gaps)")

        def numeric(name, shape):
            arr = arrays[name]
            if arr.dtype.kind not in "fiu":
                raise fail(f"array '{name}' has dtype {arr.dtype}, expected numbers")
            if arr.shape != shape:
                raise fail(f"array '{name}' has shape {arr.shape}, expected {shape}")
            arr = arr.astype(float)
            if not np.all(np.isfinite(arr)):
                raise fail(f"array '{name}' has non-finite entries")
            return arr

        first = arrays["W1"]
        if first.ndim != 2:
            raise fail(f"array 'W1' has shape {first.shape}, expected a matrix (outputs x inputs)")
        width = first.shape[1]
        n_inputs = width
        weights, biases = [], []
        for i in range(1, count + 1):
            rows = arrays[f"W{i}"].shape[0] if arrays[f"W{i}"].ndim == 2 else -1
            if rows < 1:
                raise fail(f"array 'W{i}' has shape {arrays[f'W{i}'].shape}, expected a matrix with {width} columns")
            weights.append(numeric(f"W{i}", (rows, width)))
            biases.append(numeric(f"b{i}", (rows,)))
            width = rows
        omega = float(numeric("omega", ()))
        if omega <= 0:
            raise fail("array 'omega' must be positive")
        offset = numeric("input_offset", (n_inputs,))
        scale = numeric("input_scale", (n_inputs,))
        if np.any(scale <= 0):
            raise fail("array 'input_scale' must be positive")
        digest = hashlib.sha256(raw).hexdigest()[:10]
        tag = re.sub(r"\W", "_", path.stem) + "_" + digest
        return cls(weights, biases, omega, offset, scale, tag)

    # ------------------------------------------------------------ evaluation
    def evaluate(self, *inputs) -> list:
        """All outputs at the inputs (floats, ``(N,)`` arrays, or DA numbers)."""
        if len(inputs) != self.n_inputs:
            raise TypeError(f"the network takes {self.n_inputs} inputs, got {len(inputs)}")
        da = next((v for v in inputs if hasattr(v, "affine")), None)
        if da is not None:
            h = type(da).stack([v if hasattr(v, "affine") else da * 0.0 + v for v in inputs])
            for W, b in self._hidden:
                h = h.affine(W, b).sin()
            return h.affine(*self._output).unstack()
        X = np.stack(np.broadcast_arrays(*[np.asarray(v, dtype=float) for v in inputs]))
        h = X.reshape(self.n_inputs, -1).T[:, :, None]        # (N, inputs, 1): a column per state
        for W, b in self._hidden:
            h = np.sin(np.matmul(W, h) + b[:, None])
        W, b = self._output
        out = (np.matmul(W, h) + b[:, None])[:, :, 0].T.reshape((self.n_outputs,) + X.shape[1:])
        return [float(o) for o in out] if X.ndim == 1 else list(out)

    def __call__(self, *inputs) -> list:
        """:meth:`evaluate`, reusing the last result for the same (unchanged) arguments: the same
        objects, and for arrays the same bytes (same values bit for bit give the same outputs)."""
        last = self._last
        if last is not None:
            args, snapshot, outputs = last
            if (len(args) == len(inputs) and all(a is b for a, b in zip(args, inputs))
                    and all(s is None or _snapshot(a) == s for a, s in zip(inputs, snapshot))):
                return outputs
        outputs = self.evaluate(*inputs)
        snapshot = [_snapshot(a) if isinstance(a, np.ndarray) else None for a in inputs]
        self._last = (inputs, snapshot, outputs)
        return outputs

    # ------------------------------------------------------------ symbolic
    def functions(self) -> list:
        """One sympy implemented function per output, named ``siren_<tag>_<k>``."""
        if self._functions is None:
            self._functions = [UndefinedFunction(f"siren_{self.tag}_{k}", _imp_=SirenOutput(self, k))
                               for k in range(self.n_outputs)]
        return self._functions

    def law(self, symbols: list[sympy.Symbol]) -> list[sympy.Expr]:
        """The outputs as sympy expressions of the feedback state symbols."""
        return [f(*symbols) for f in self.functions()]


def _snapshot(a: np.ndarray) -> tuple:
    """What identifies an array's contents: type, shape and bytes."""
    return a.dtype, a.shape, a.tobytes()


class SirenOutput:
    """Output ``k`` of a network as a picklable callable (the ``_imp_`` of its sympy function).
    Two are equal when they name the same output of the same weights file (its digest is in the
    tag), as sympy compares functions by these attributes."""

    def __init__(self, net: Siren, k: int):
        self.net, self.k = net, k
        self.__name__ = f"siren_{net.tag}_{k}"

    def __call__(self, *inputs):
        return self.net(*inputs)[self.k]

    def __eq__(self, other):
        return isinstance(other, SirenOutput) and (self.net.tag, self.k) == (other.net.tag, other.k)

    def __hash__(self):
        return hash((self.net.tag, self.k))
