"""Why a stage failed: the one documented set of ``failure_reason`` codes (docs/executors.md).

Every stage result carries ``failure_reason``: "" on success, otherwise exactly one
code below. Free text about the failure goes to ``failure_detail``.
"""

from __future__ import annotations

INVALID_PREDICTION = "invalid_prediction"      # the cross-pose is not a finite 4x4 matrix
GRASP_MISSED = "grasp_missed"                  # the fingers closed on nothing (or on the wrong body)
SLIPPED = "slipped"                            # the grasp held, then the object left the fingers
PLANNING_FAILED = "planning_failed"            # no path (no grasp candidate, planner gave up)
UNREACHABLE = "unreachable"                    # the hand or arm cannot get to a required pose
COLLISION = "collision"                        # the hand or held object was stopped by the furniture
STALLED_AGAINST_HINGE = "stalled_against_hinge"  # the hand pulled against the joint and could not follow the path
NOT_OPEN_ENOUGH = "not_open_enough"            # executed, but the door or drawer stopped short of open
NOT_IN_REGION = "not_in_region"                # executed, but the object came to rest outside the goal region
NOT_AT_REST = "not_at_rest"                    # executed, but the scene was still moving when time ran out
BLOW_UP = "blow_up"                            # the simulation produced non-finite or runaway velocities

FAILURE_REASONS = (
    INVALID_PREDICTION, GRASP_MISSED, SLIPPED, PLANNING_FAILED, UNREACHABLE, COLLISION,
    STALLED_AGAINST_HINGE, NOT_OPEN_ENOUGH, NOT_IN_REGION, NOT_AT_REST, BLOW_UP,
)


def check_reason(reason: str) -> str:
    """``reason`` if it is "" or a known code; ValueError otherwise (keeps the set closed)."""
    if reason and reason not in FAILURE_REASONS:
        raise ValueError(f"unknown failure reason {reason!r}; valid: {', '.join(FAILURE_REASONS)}")
    return reason
