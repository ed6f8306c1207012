"""The declared grey-box models by name (``cdam residual --model NAME``)."""
from __future__ import annotations

from cdam_core.models.greybox.declared import FlexibleJoint, GreyBoxModel, RigidAxis
from cdam_core.models.greybox.flight import AerialManipulator, Quadrotor

__all__ = ["MODEL_NAMES", "get_model"]

_MODELS = {"rigid_axis": RigidAxis, "flexible_joint": FlexibleJoint, "quadrotor": Quadrotor,
           "aerial_manipulator": AerialManipulator}
MODEL_NAMES = tuple(_MODELS)


def get_model(name: str, fixed: dict | None = None) -> GreyBoxModel:
    """The declared model called ``name``: ``rigid_axis``, ``flexible_joint``, ``quadrotor``
    or ``aerial_manipulator``."""
    if not isinstance(name, str) or name not in _MODELS:
        raise ValueError(f"model: unknown model {name!r}; available: {', '.join(MODEL_NAMES)}")
    return _MODELS[name](fixed)
