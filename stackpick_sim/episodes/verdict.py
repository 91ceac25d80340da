"""The verdict after verify: was the right object picked, held high enough, nothing knocked off.

``success`` is defined as: the picked object was a true top object at detection time, rests
held by the suction cup at least :data:`MIN_LIFT_M` above its starting height after the
lift, and no other object was knocked off the belt (objects carried past the belt's end by
the belt are not "knocked off").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from stackpick_sim.episodes.outcome import touching
from stackpick_sim.episodes.record import MIN_LIFT_M

if TYPE_CHECKING:
    from stackpick_sim.episodes.episode import Episode


def judge(ep: Episode, start_z: dict[str, float], grasped: list[str]) -> None:
    """Fill in the record's success, failure, picked object, lift and knocked-off objects.

    ``start_z``: each object's centre height at detection time, m; ``grasped``: objects
    touching the cup when the lift began.
    """
    rec = ep.record
    cell = ep.scene.cell
    held = touching(cell, ep.lips)
    removed = set(ep.conveyor.removed)
    rec.knocked_off = [o.name for o in cell.objects
                       if o.name not in removed and o.name not in {h.name for h in held}
                       and cell.fell_off_belt(o)]
    if held:
        # With two objects at the cup (rare), the higher one is what the cup carries.
        obj = max(held, key=lambda o: float(cell.data.xpos[o.body_id][2]))
        rec.picked_object = obj.name
        rec.lift_height_m = float(cell.data.xpos[obj.body_id][2]) - start_z.get(obj.name, 0.0)
    if not held:
        reason = "dropped" if grasped else "missed_grasp"
        detail = (f"{', '.join(grasped)} left the cup during the lift" if grasped
                  else "nothing was held by the suction cup")
    elif rec.picked_object not in rec.top_objects:
        reason, detail = "wrong_object", (f"picked {rec.picked_object}, true top objects "
                                          f"{rec.top_objects}")
    elif rec.lift_height_m is None or rec.lift_height_m < MIN_LIFT_M:
        reason, detail = "dropped", f"object only {rec.lift_height_m:.3f} m above its start"
    elif rec.knocked_off:
        reason, detail = "dropped", f"knocked off the belt: {', '.join(rec.knocked_off)}"
    else:
        rec.success = True
        return
    rec.failure = reason
    rec.failure_detail = detail
    rec.failed_phase = "verify"
