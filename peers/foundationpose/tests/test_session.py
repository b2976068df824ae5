"""The session against the stand-in: depth normalisation, register/track/reset, refusals."""
import os
import tempfile
import unittest

import numpy as np

from hitl_foundationpose.session import FrameRefused, Options, Session, Shared
from tests import helpers
from tests.helpers import calls, frame, reply_pose, true_centroid


class SessionTest(unittest.TestCase):
    def setUp(self):
        self.fp = helpers.stand_in()
        self.tmp = tempfile.TemporaryDirectory()
        self.addCleanup(self.tmp.cleanup)
        self.shared = Shared(self.fp)

    def session(self, **opts):
        opts.setdefault("debug_dir", self.tmp.name)
        v, f = helpers.box_mesh(0.4)
        s = Session(self.fp, self.shared, v, f, Options(**opts))
        self.addCleanup(s.close)
        return s

    def test_depth_is_normalised_to_a_1m_median_and_the_translation_scaled_back(self):
        s = self.session()
        header, arrays = frame(0, median_m=4.0)
        reply = s.frame(header, arrays)
        self.assertEqual(reply["kind"], "registered")
        (reg,) = calls(self.fp, "register")
        # FoundationPose saw the target's median depth at 1 m and no non-finite depth.
        self.assertAlmostEqual(reg["median_depth"], 1.0, places=12)
        self.assertEqual(reg["nonfinite"], 0)
        # ... and the mesh scaled by the same 1/4 (0.4 m box -> 0.1 m).
        self.assertAlmostEqual(calls(self.fp, "reset_object")[-1]["extent"], 0.1, places=12)
        # Its translation comes back x4, and that is the target's centroid in real metres.
        p = reply_pose(reply)
        np.testing.assert_allclose(p[:3, 3], 4.0 * np.array(reg["returned_t"]), rtol=1e-12)
        np.testing.assert_allclose(p[:3, 3], true_centroid(arrays), rtol=1e-6)
        self.assertGreater(p[2, 3], 3.5)
        # Rotation unchanged.
        np.testing.assert_allclose(p[:3, :3], self.fp.R_FIXED, atol=1e-15)
        np.testing.assert_array_equal(p[3], [0, 0, 0, 1])

    def test_a_new_median_while_tracking_rescales_the_mesh_and_the_remembered_pose(self):
        s = self.session()
        h0, a0 = frame(0, median_m=4.0)
        r0 = s.frame(h0, a0)
        h1, a1 = frame(1, median_m=2.0)
        r1 = s.frame(h1, a1)
        self.assertEqual(r1["kind"], "tracked")
        (track,) = calls(self.fp, "track_one")
        self.assertAlmostEqual(track["median_depth"], 1.0, places=12)
        self.assertEqual(track["nonfinite"], 0)
        self.assertAlmostEqual(calls(self.fp, "reset_object")[-1]["extent"], 0.2, places=12)
        # The pose remembered from frame 0 (in its 1/4 metres) is handed over in frame 1's 1/2.
        np.testing.assert_allclose(track["pose_last_t"], reply_pose(r0)[:3, 3] / 2.0, rtol=1e-12)
        np.testing.assert_allclose(reply_pose(r1)[:3, 3], true_centroid(a1), rtol=1e-6)
        np.testing.assert_allclose(reply_pose(r1)[:3, 3], 2.0 * np.array(track["returned_t"]),
                                   rtol=1e-12)

    def test_registers_first_and_after_each_reset_and_tracks_between(self):
        s = self.session()
        kinds = []
        for seq in range(3):
            kinds.append(s.frame(*frame(seq, median_m=1.5))["kind"])
        s.reset()
        s.reset()
        for seq in range(3, 5):
            kinds.append(s.frame(*frame(seq, median_m=1.5))["kind"])
        self.assertEqual(kinds, ["registered", "tracked", "tracked", "registered", "tracked"])
        fp_calls = [(c["call"], c["iteration"]) for c in calls(self.fp)
                    if c["call"] in ("register", "track_one")]
        self.assertEqual(fp_calls, [("register", 5), ("track_one", 2), ("track_one", 2),
                                    ("register", 5), ("track_one", 2)])

    def test_iterations_are_options(self):
        s = self.session(register_iterations=7, track_iterations=3)
        s.frame(*frame(0, median_m=1.0))
        s.frame(*frame(1, median_m=1.0))
        self.assertEqual([c["iteration"] for c in calls(self.fp) if "iteration" in c], [7, 3])

    def test_a_frame_without_a_mask_is_refused_and_changes_nothing(self):
        s = self.session()
        with self.assertRaises(FrameRefused) as e:
            s.frame(*frame(0, median_m=4.0, mask=False))
        self.assertIn("frame 0 has no target mask", str(e.exception))
        self.assertEqual(calls(self.fp, "register"), [])
        self.assertEqual(s.frame(*frame(1, median_m=4.0))["kind"], "registered")
        with self.assertRaises(FrameRefused):
            s.frame(*frame(2, median_m=4.0, mask=False))
        self.assertEqual(s.frame(*frame(3, median_m=4.0))["kind"], "tracked")
        self.assertEqual(len(calls(self.fp, "register")) + len(calls(self.fp, "track_one")), 2)

    def test_a_frame_without_colour_or_with_the_wrong_size_is_refused(self):
        s = self.session()
        with self.assertRaises(FrameRefused) as e:
            s.frame(*frame(0, median_m=4.0, color=False))
        self.assertIn("frame 0 has no colour", str(e.exception))
        header, arrays = frame(1, median_m=4.0)
        arrays["mask"] = arrays["mask"][:-1]
        with self.assertRaises(FrameRefused) as e:
            s.frame(header, arrays)
        self.assertIn("`mask` must be u1 [24,32]", str(e.exception))
        self.assertEqual(calls(self.fp, "register"), [])

    def test_no_target_depth_is_lost_and_the_next_frame_registers(self):
        s = self.session()
        s.frame(*frame(0, median_m=2.0))
        header, arrays = frame(1, median_m=2.0)
        arrays["depth"] = np.full_like(arrays["depth"], np.nan)
        self.assertEqual(s.frame(header, arrays), {"type": "pose", "seq": 1, "pose": None,
                                                   "kind": "lost"})
        self.assertEqual(s.frame(*frame(2, median_m=2.0))["kind"], "registered")

    def test_foundationposes_identity_rotation_is_lost_and_the_next_frame_registers(self):
        s = self.session()
        header, arrays = frame(0, median_m=2.0, invalid=False)
        keep = np.zeros_like(arrays["depth"])
        keep[10, 10:13] = arrays["depth"][10, 10:13]  # 3 target pixels: FoundationPose gives up
        arrays["depth"] = keep
        reply = s.frame(header, arrays)
        self.assertIsNone(reply["pose"])
        self.assertEqual(reply["kind"], "lost")
        self.assertEqual(calls(self.fp, "register")[-1]["valid"], 3)
        self.assertEqual(s.frame(*frame(1, median_m=2.0))["kind"], "registered")

    def test_a_foundationpose_exception_is_refused_and_the_next_frame_registers(self):
        s = self.session()
        s.frame(*frame(0, median_m=2.0))
        s.est.pose_last = None  # track_one raises RuntimeError, as the real one does
        with self.assertRaises(FrameRefused) as e:
            s.frame(*frame(1, median_m=2.0))
        self.assertIn("FoundationPose failed on frame 1 (track_one): RuntimeError",
                      str(e.exception))
        self.assertEqual(s.frame(*frame(2, median_m=2.0))["kind"], "registered")

    def test_rescale_tolerance_keeps_the_mesh_and_stays_a_similarity(self):
        s = self.session(rescale_tolerance=0.1)
        header, arrays = frame(0, median_m=1.05)
        reply = s.frame(header, arrays)
        self.assertEqual(len(calls(self.fp, "reset_object")), 1)  # the constructor's only
        self.assertAlmostEqual(calls(self.fp, "register")[-1]["median_depth"], 1.05, places=6)
        np.testing.assert_allclose(reply_pose(reply)[:3, 3], true_centroid(arrays), rtol=1e-6)
        s.frame(*frame(1, median_m=1.3))  # outside: rescaled to the median
        self.assertAlmostEqual(calls(self.fp, "reset_object")[-1]["extent"], 0.4 / 1.3, places=6)
        self.assertAlmostEqual(calls(self.fp, "track_one")[-1]["median_depth"], 1.0, places=6)

    def test_mesh_files_foundationpose_leaves_are_removed(self):
        s = self.session()
        for seq, m in enumerate([4.0, 3.0, 2.0]):
            s.frame(*frame(seq, median_m=m))
        paths = [c["mesh_path"] for c in calls(self.fp, "reset_object")]
        self.assertEqual(len(paths), 4)
        self.assertEqual([os.path.exists(p) for p in paths], [False, False, False, True])
        s.close()
        self.assertFalse(os.path.exists(paths[-1]))

    def test_networks_are_built_once_and_shared_and_the_mesh_colour_is_an_option(self):
        self.session()
        self.session(mesh_color=[204, 204, 204])
        names = [c["call"] for c in calls(self.fp)]
        self.assertEqual(names.count("ScorePredictor"), 1)
        self.assertEqual(names.count("PoseRefinePredictor"), 1)
        self.assertEqual(names.count("RasterizeCudaContext"), 1)
        self.assertEqual([c["shared"] for c in calls(self.fp, "FoundationPose")], [True, True])
        self.assertEqual([c["color"] for c in calls(self.fp, "reset_object")],
                         [[102, 102, 102], [204, 204, 204]])


if __name__ == "__main__":
    unittest.main()
