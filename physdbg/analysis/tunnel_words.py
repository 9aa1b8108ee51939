"""Why a sphere crossed a body with no contact, and what to do about it: the one
vocabulary that ``physdbg explain``'s tunnelling findings, ``physdbg diff``'s tunnelling
causes and ``physdbg check-run``'s tunnelling departures speak.

The reason comes from what the run says of itself: another engine's step (tested, it
seems, where the step ends), a detection that tests only some instants, a budget that
left the rest of the step unresolved, ``ordering = index`` (a contact an earlier one
creates is not looked for), or none of these (a swept, time-ordered physdbg run that
should never cross: a fault to report).
"""

from __future__ import annotations

from dataclasses import dataclass, field

# another engine's run: it let a sphere cross within one step, so it tested where steps end
FOREIGN_ADVICE = ("test for contacts along the path through the step (a swept test: solve for the time of impact), "
                  "not where the step ends, or take shorter steps")
SWEPT_ADVICE = "use detection = swept (exact time of impact), or a shorter dt"


@dataclass(frozen=True)
class TunnelWhy:
    """reason: why the run let the sphere cross, in words that follow "with no contact";
    advice: what to change (each "" where the other says it); settings: the advice as the
    settings a fork can try from the step on ({} where it is not one)."""

    reason: str
    advice: str
    settings: dict = field(default_factory=dict)


def why_tunnelled(settings: dict, budgets: list[str], foreign: bool = False, pair: bool = False,
                  pile: str | None = None) -> TunnelWhy:
    """Why a step let a sphere cross a body with no contact. settings: the run's recorded
    settings; budgets: the codes of the work budgets (max_…) the step hit, in order;
    foreign: the run is another engine's; pair: the body crossed is another sphere;
    pile: advisor.pile_hint for the run, added to a budget's advice (None: no pile)."""
    if foreign:
        return TunnelWhy("the other engine let it cross within one step", FOREIGN_ADVICE)
    detection = settings.get("detection", "swept")
    if detection in ("discrete", "sampled"):  # a test only at some instants: the first cause, whatever followed
        reason = ("detection = discrete tests only where each step ends" if detection == "discrete" else
                  f"detection = sampled tests only {settings.get('samples', 4)} instants a step")
        return TunnelWhy(reason, SWEPT_ADVICE + (
            f" (this step also hit the {budgets[0]} budget: spheres left inside a thin wall by the missed "
            f"contacts keep meeting it)" if budgets else ""), {"detection": "swept"})
    if budgets and budgets[0] == "max_memory":
        return TunnelWhy("the step reached max_memory, so contacts after it were not resolved",
                         "this step reached max_memory, so contacts after it were not resolved: raise it (the "
                         "step's warning names a value), or record at --detail contacts, which logs only the "
                         "swept tests that hit")
    if budgets:
        return TunnelWhy(f"the step hit the {budgets[0]} budget, so contacts after it were not resolved",
                         f"this step hit the {budgets[0]} budget, so contacts after it were not resolved: "
                         f"raise it, or let slow contacts rest (rest_fraction)" + (f"; {pile}" if pile else ""))
    if detection != "swept":
        return TunnelWhy(f"detection = {detection}", SWEPT_ADVICE, {"detection": "swept"})
    if settings.get("ordering") == "index" and pair:
        return TunnelWhy("ordering = index: a contact that an earlier one creates is not looked for",
                         "ordering = index resolves the step's predicted contacts in index order, so a contact "
                         "that an earlier one creates is missed: use ordering = time")
    return TunnelWhy("a swept, time-ordered run should never do this",
                     "a swept, time-ordered run should never do this: please report it with the recording")


__all__ = ["FOREIGN_ADVICE", "TunnelWhy", "why_tunnelled"]
