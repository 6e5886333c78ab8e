"""The extension seam: optional effects that plug into M0.

An extension is a physical effect with a *strength* parameter whose zero
value gives M0 exactly. The assembly in :mod:`pyomo_heli.physics.model` calls
each extension's hooks at fixed points of the calculation, in this order:

1. ``adjust_geometry(ctx)``  may change ``ctx.x_h`` / ``ctx.l_t`` (CG position)
2. ``adjust_controls(ctx)``  may change ``ctx.col`` / ``ctx.lon`` (rigging)
3. ``tip_path_plane(ctx)``   may replace ``ctx.beta_1c_tpp`` (flapping lag)
4. ``adjust_inflow(ctx)``    may change ``ctx.tau_lambda``
5. ``tail_downwash(ctx)``    returns a downwash at the tail [m/s] (summed)
6. ``extra_forces(ctx)``     returns (dX, dZ, dM) [N, N, N m] (summed)
7. ``state_equations(ctx)``  for extra states: name -> (coef, rhs) meaning
                             coef * d(state)/dt = rhs (``ctx.true_outputs``: the outputs
                             before any sensor effect, e.g. for a sensor lag)
8. ``adjust_outputs(ctx)``   may change entries of ``ctx.outputs`` (sensors); an output's own lag
                             (``output_stage`` 0) first, so that the other sensor effects act on
                             what it holds, then the rest in the order of the extensions

The same extension object serves the float simulator, Pyomo collocation and
trim blocks, because hooks only do arithmetic on what ``ctx`` holds, with
``ctx.ops`` for functions. Parameters an extension needs are declared by
``parameters()`` and are read from ``ctx.p`` like any model parameter, so a
strength can be fixed, or free in an identification.
"""
from __future__ import annotations

from typing import Any

from .parameters import ParameterSpec


class Extension:
    """Base class: every hook is a no-op, so a subclass overrides what it needs."""

    #: short identifier, used in configs and reports
    name: str = "extension"
    #: name of the strength parameter (zero gives M0)
    strength: str = ""
    #: names of extra differential states this extension adds
    states: tuple[str, ...] = ()
    #: when ``adjust_outputs`` runs: 0 for the lag of an output (the record holds the lagged value, which a scale
    #: or bias then acts on), 1 for every other sensor effect
    output_stage: int = 1

    def parameters(self) -> list[ParameterSpec]:
        """Parameter specs this extension adds (the strength first)."""
        return []

    def describe(self) -> str:
        return (self.__doc__ or self.name).strip().splitlines()[0]

    # hooks --------------------------------------------------------------
    def adjust_geometry(self, ctx) -> None:
        pass

    def adjust_controls(self, ctx) -> None:
        pass

    def tip_path_plane(self, ctx) -> None:
        pass

    def adjust_inflow(self, ctx) -> None:
        pass

    def tail_downwash(self, ctx) -> Any:
        return 0.0

    def extra_forces(self, ctx) -> tuple[Any, Any, Any]:
        return 0.0, 0.0, 0.0

    def state_equations(self, ctx) -> dict[str, tuple[Any, Any]]:
        return {}

    def trim_guess(self, ctx) -> dict[str, float]:
        """Initial values of the extra states at a trim (from quasi-steady values)."""
        return {}

    def adjust_outputs(self, ctx) -> None:
        pass

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


class PitchMomentOffset(Extension):
    """A constant pitching-moment increment dM = M0_offset (a minimal test extension).

    Useful to test the seam and as a generic "unexplained moment" candidate.
    """

    name = "pitch_moment_offset"
    strength = "dM_offset"

    def parameters(self):
        return [ParameterSpec("dM_offset", 0.0, "N m", "constant pitching-moment increment", "choice",
                              (-5000.0, 5000.0), 1000.0)]

    def extra_forces(self, ctx):
        return 0.0, 0.0, ctx.p["dM_offset"]


def extension_forms(extensions) -> dict:
    """name -> short hash of the extension class's source: tells a result of an older form of an effect apart."""
    import hashlib
    import inspect

    out = {}
    for e in extensions:
        try:
            src = inspect.getsource(type(e))
        except (OSError, TypeError):
            src = type(e).__qualname__
        out[e.name] = hashlib.sha1(src.encode()).hexdigest()[:12]
    return out
