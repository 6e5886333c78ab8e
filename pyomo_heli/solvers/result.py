"""Backend-neutral solve result and Ipopt's status vocabulary.

All backends are Ipopt (inside casadi) or Ipopt-compatible (pounce, an
``ipopt`` executable), so Ipopt's ``ApplicationReturnStatus`` names are used
as the common status language. The AMPL backends only report the ``EXIT:``
text in their log, hence the message <-> status table here.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Statuses counted as a successful solve. ``status`` tells them apart:
#: an "acceptable" point deserves a look before it is trusted.
SUCCESS_STATUSES = frozenset({"Solve_Succeeded", "Solved_To_Acceptable_Level"})

#: Ipopt return status -> the text Ipopt prints after ``EXIT:``.
IPOPT_EXIT_MESSAGES = {
    "Solve_Succeeded": "Optimal Solution Found.",
    "Solved_To_Acceptable_Level": "Solved To Acceptable Level.",
    "Infeasible_Problem_Detected": "Converged to a point of local infeasibility. Problem may be infeasible.",
    "Search_Direction_Becomes_Too_Small": "Search Direction is becoming Too Small.",
    "Diverging_Iterates": "Iterates diverging; problem might be unbounded.",
    "User_Requested_Stop": "Stopping optimization at current point as requested by user.",
    "Feasible_Point_Found": "Feasible point for square problem found.",
    "Maximum_Iterations_Exceeded": "Maximum Number of Iterations Exceeded.",
    "Restoration_Failed": "Restoration Failed!",
    "Error_In_Step_Computation": "Error in step computation!",
    "Maximum_CpuTime_Exceeded": "Maximum CPU time exceeded.",
    "Maximum_WallTime_Exceeded": "Maximum wallclock time exceeded.",
    "Not_Enough_Degrees_Of_Freedom": "Problem has too few degrees of freedom.",
    "Invalid_Problem_Definition": "Problem has inconsistent variable bounds or constraint sides.",
    "Invalid_Option": "Invalid option encountered.",
    "Invalid_Number_Detected": "Invalid number in NLP function or derivative detected.",
    "Unrecoverable_Exception": "Some uncaught Ipopt exception encountered.",
    "NonIpopt_Exception_Thrown": "Unknown Exception caught in Ipopt.",
    "Insufficient_Memory": "Not enough memory.",
    "Internal_Error": "INTERNAL ERROR: Unknown SolverReturn value - Notify IPOPT Authors.",
}


def status_from_exit_message(text: str) -> str | None:
    """Map an ``EXIT:`` message back to the Ipopt status name (None if unknown)."""
    key = text.strip().rstrip(".").lower()
    for status, message in IPOPT_EXIT_MESSAGES.items():
        if message.rstrip(".").lower() == key:
            return status
    return None


@dataclass
class SolveResult:
    """Outcome of one NLP solve, the same for every backend.

    ``wall_time`` is the solve itself; ``setup_time`` is the one-off work
    before it (NL writing, casadi import, ``nlpsol`` build), 0 when a cached
    problem is re-solved. For the AMPL backends, which rewrite the NL file on
    every call, the NL write is inside ``wall_time`` and ``setup_time`` is 0.
    """

    success: bool
    status: str
    message: str
    iterations: int
    objective: float
    wall_time: float
    setup_time: float
    solver: str

    @property
    def acceptable_only(self) -> bool:
        """True when Ipopt stopped at its looser 'acceptable' tolerances."""
        return self.status == "Solved_To_Acceptable_Level"

    def __str__(self) -> str:
        rows = [
            ("solver", self.solver),
            ("success", str(self.success)),
            ("status", self.status),
            ("message", self.message),
            ("iterations", str(self.iterations)),
            ("objective", f"{self.objective:.10g}"),
            ("wall time [s]", f"{self.wall_time:.3f}"),
            ("setup time [s]", f"{self.setup_time:.3f}"),
        ]
        width = max(len(name) for name, _ in rows)
        return "\n".join(f"{name:<{width}} : {value}" for name, value in rows)
