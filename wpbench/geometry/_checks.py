"""Input validation shared by the geometry modules.

Every public geometry function checks shapes and dtypes up front so a caller
gets a ``ValueError`` that names the argument and the expected shape, instead
of an obscure broadcasting or matmul error deep inside the maths.
"""

from __future__ import annotations

import torch

SUPPORTED_DTYPES = (torch.float32, torch.float64)


def require_tensor(name: str, value: object) -> torch.Tensor:
    """Return ``value`` if it is a float32/float64 tensor, else raise ValueError."""
    if not isinstance(value, torch.Tensor):
        raise ValueError(
            f"{name} must be a torch.Tensor, got {type(value).__name__}; "
            "wrap arrays with torch.as_tensor(x, dtype=torch.float32)"
        )
    if value.dtype not in SUPPORTED_DTYPES:
        raise ValueError(
            f"{name} has dtype {value.dtype}; geometry functions take float32 or float64, "
            f"cast with {name}.float() or {name}.double()"
        )
    return value


def require_trailing(name: str, value: torch.Tensor, trailing: tuple[int, ...], describe: str) -> None:
    """Raise ValueError unless ``value.shape`` ends with ``trailing``.

    ``describe`` is the human-readable expected shape, e.g. ``"(..., 3, 3)"``.
    """
    require_tensor(name, value)
    if value.dim() < len(trailing) or tuple(value.shape[-len(trailing):]) != trailing:
        raise ValueError(f"{name} must have shape {describe}, got {tuple(value.shape)}")


def require_shape(name: str, value: torch.Tensor, shape: tuple[int | None, ...], describe: str) -> None:
    """Raise ValueError unless ``value`` has exactly ``len(shape)`` dims matching ``shape``.

    ``None`` entries in ``shape`` match any size.
    """
    require_tensor(name, value)
    ok = value.dim() == len(shape) and all(
        want is None or want == got for want, got in zip(shape, value.shape)
    )
    if not ok:
        raise ValueError(f"{name} must have shape {describe}, got {tuple(value.shape)}")


def require_same_dtype(**tensors: torch.Tensor) -> torch.dtype:
    """Raise ValueError if the given tensors do not share one dtype; return it."""
    dtypes = {name: t.dtype for name, t in tensors.items()}
    if len(set(dtypes.values())) > 1:
        listing = ", ".join(f"{name}={dtype}" for name, dtype in dtypes.items())
        raise ValueError(f"inputs must share one dtype, got {listing}; cast them with .to(dtype)")
    return next(iter(dtypes.values()))
