"""scikit-learn's estimator protocol, written here so that scikit-learn stays optional.

Why not derive from ``sklearn.base.BaseEstimator``: scikit-learn (with joblib and threadpoolctl)
would become a run-time dependency of every install, the firmware and CLI paths included, for
three methods. What scikit-learn needs from an estimator is a protocol, not a base class:
``get_params``/``set_params`` read the ``__init__`` signature; ``__sklearn_is_fitted__``;
``n_features_in_``; ``__sklearn_tags__`` (imports scikit-learn lazily: only scikit-learn calls
it). With these, ``clone``, ``Pipeline``, ``GridSearchCV`` and ``check_estimator`` work
(tests/models/test_sklearn.py).

Contract for a subclass (scikit-learn's): ``__init__`` stores every argument unchanged under
its own name (it may validate, and does: the project refuses a bad argument where it is given);
fitted state ends in ``_``. ``set_params`` validates the new values the same way, by
constructing a fresh instance from them, and changes nothing when they are refused.
"""
from __future__ import annotations

import inspect

__all__ = ["EstimatorParams"]


class EstimatorParams:
    """get_params / set_params and the tags scikit-learn reads (see the module doc)."""

    _estimator_type = "regressor"        # or "transformer"

    @classmethod
    def _get_param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return sorted(p.name for p in sig.parameters.values()
                      if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD))

    def get_params(self, deep: bool = True) -> dict:
        """{name: value} of the ``__init__`` arguments (with ``deep``, nested estimators'
        parameters as ``name__param`` too)."""
        out = {}
        for name in self._get_param_names():
            value = getattr(self, name)
            if deep and hasattr(value, "get_params") and not isinstance(value, type):
                out.update((f"{name}__{k}", v) for k, v in value.get_params().items())
            out[name] = value
        return out

    def set_params(self, **params):
        """Set ``__init__`` arguments (``name__param`` for a nested estimator); returns self.
        Refused values (ValueError naming them, as ``__init__`` does) change nothing."""
        if not params:
            return self
        names = self._get_param_names()
        own, nested = {}, {}
        for key, value in params.items():
            name, _, sub = key.partition("__")
            if name not in names:
                raise ValueError(f"{key}: not a parameter of {type(self).__name__}; "
                                 f"parameters: {', '.join(names)}")
            if sub:
                nested.setdefault(name, {})[sub] = value
            else:
                own[name] = value
        candidate = {**self.get_params(deep=False), **own}
        type(self)(**candidate)                     # validates; raises before any change
        for name, value in own.items():
            setattr(self, name, value)
        for name, sub in nested.items():
            getattr(self, name).set_params(**sub)
        return self

    def __repr__(self) -> str:
        """``Name(param=value, ...)`` with the parameters that differ from their defaults."""
        sig = inspect.signature(type(self).__init__).parameters
        parts = []
        for name in self._get_param_names():
            value, default = getattr(self, name, None), sig[name].default
            try:
                same = bool(value == default)
            except (ValueError, TypeError):       # arrays and the like
                same = False
            if not same:
                parts.append(f"{name}={value!r}")
        return f"{type(self).__name__}({', '.join(parts)})"

    def __sklearn_is_fitted__(self) -> bool:
        return bool(self.is_fitted())

    def is_fitted(self) -> bool:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    def _n_features(self) -> int:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    @property
    def n_features_in_(self) -> int:
        """Input columns seen by fit (scikit-learn's name); AttributeError before fit."""
        if not self.is_fitted():
            raise AttributeError("n_features_in_: not fitted")
        return int(self._n_features())

    def __sklearn_tags__(self):
        from sklearn.utils import InputTags, RegressorTags, Tags, TargetTags, TransformerTags
        regressor = self._estimator_type == "regressor"
        return Tags(estimator_type=self._estimator_type,
                    target_tags=TargetTags(required=regressor, one_d_labels=False,
                                           two_d_labels=False, positive_only=False,
                                           multi_output=regressor, single_output=True),
                    transformer_tags=None if regressor else TransformerTags(),
                    # a dynamic model on scikit-learn's i.i.d. check data (no dynamics to
                    # learn, free run from the start outputs) cannot score well: poor_score
                    regressor_tags=RegressorTags(poor_score=bool(getattr(self, "dynamic",
                                                                         False)))
                    if regressor else None,
                    input_tags=InputTags())
