"""evo's side of `tests/eval.rs`: ATE (SE(3), Sim(3) and no alignment) and RPE (translation,
rotation in degrees) for each trajectory pair of the job, with evo's own association. A
case with `"gt_format": "euroc"` reads its ground truth as `evo_ape euroc` does."""
import copy
import json
import sys

from evo.core import metrics, sync
from evo.tools import file_interface

out = []
for case in json.load(open(sys.argv[1])):
    if case.get("gt_format") == "euroc":
        ref = file_interface.read_euroc_csv_trajectory(case["gt"])
    else:
        ref = file_interface.read_tum_trajectory_file(case["gt"])
    est = file_interface.read_tum_trajectory_file(case["est"])
    ref, est = sync.associate_trajectories(ref, est, max_diff=case["max_diff"])
    res = {"matched": ref.num_poses}
    for align in ["se3", "sim3", "none"]:
        e = copy.deepcopy(est)
        if align != "none":  # evo_ape without -a: the estimate as it is
            e.align(ref, correct_scale=(align == "sim3"))
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((ref, e))
        res["ate_" + align] = ape.get_all_statistics()
        for relation, name in [
            (metrics.PoseRelation.translation_part, "rpe_t"),
            (metrics.PoseRelation.rotation_angle_deg, "rpe_r"),
        ]:
            unit = metrics.Unit.meters if case.get("unit") == "m" else metrics.Unit.frames
            rpe = metrics.RPE(relation, delta=case["delta"], delta_unit=unit, all_pairs=False)
            rpe.process_data((ref, e))
            res[name + "_" + align] = rpe.get_all_statistics()
    out.append(res)
print(json.dumps(out))
