"""The detector and the evidence map as one stage: what the graph reports on /obstacles.

`Perception.process` runs `core.gpod.GpodDetector.process` on a stereo pair, then (with
``EvidenceMapConfig.enabled``) enters the pair's matched edge pixels into the evidence
map (`core.evidence_map`) and reports the map's confirmed regions instead of the
detector's detections and tracks. The map's camera motion is the one given with the
pair, or, with a `core.map_motion.MotionPredictor` (``motion_predictor``), the
predictor's for the pair: from the motions measured before it, so that nobody waits for
the pair's own (the detector node feeds the predictor the egomotion's odometry as it
arrives); the detector carries its ground surface ahead through the same motion
(`core.surface_tracking`), the predictor asked once per pair. The detector node and the
offline evaluation
(`asmonc eval`, `asmonc bench`'s runs) both drive the detector through this class, so
the offline numbers are what the graph publishes.
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

from asmonc_vision.core.camera import StereoCamera
from asmonc_vision.core.evidence_map import EvidenceMap, EvidenceMapConfig
from asmonc_vision.core.map_evidence import DROP, GROUND, NONE, RAISED, pair_evidence
from asmonc_vision.core.gpod import GpodConfig, GpodDetector, GpodResult
from asmonc_vision.core.map_motion import MotionPredictor
from asmonc_vision.core.map_steps import ground_step, may_step, with_step
from asmonc_vision.core.map_reports import objects_to_obstacles
from asmonc_vision.core.moving_reports import ChainedReports, TallReports, report_arrays
from asmonc_vision.core.npfast import flat_nonzero


class Perception:
    """GpodDetector followed by the evidence map (when enabled).

    Attributes:
        detector: the GpodDetector.
        map: the EvidenceMap (None when ``map_config.enabled`` is false).
        motion_predictor: None, the map takes the motion given to `process`; else the
            map takes this predictor's motion for each pair (the caller feeds it the
            measured motions as they come).
    """

    def __init__(self, gpod_config: GpodConfig | None = None,
                 map_config: EvidenceMapConfig | None = None,
                 motion_predictor: MotionPredictor | None = None) -> None:
        self.gpod_config = gpod_config or GpodConfig()
        self.map_config = map_config or EvidenceMapConfig()
        self.detector = GpodDetector(self.gpod_config)
        self.map = EvidenceMap(self.map_config) if self.map_config.enabled else None
        self.motion_predictor = motion_predictor
        self.tall = TallReports.from_config(self.map_config)
        self.unmapped = ChainedReports.from_config(self.map_config)
        #: the map has placed min_placed_pairs pairs in a row since the last reset, or
        #: start_raw_s has passed since the first pair with a plane: the detector's own
        #: reports go out only chained
        self.past_start = False
        #: stamp of the first pair with a ground plane since the last reset, s
        self._first_plane_s: float | None = None

    @property
    def config(self) -> GpodConfig:
        """The detector's settings."""
        return self.gpod_config

    def reset(self) -> None:
        """Restart the detector and forget the map (and the predictor's motions)."""
        self.detector.reset()
        self.tall.reset()
        self.unmapped.reset()
        self.past_start = False
        self._first_plane_s = None
        if self.map is not None:
            self.map.reset()
        if self.motion_predictor is not None:
            self.motion_predictor.reset()

    def process(self, left: np.ndarray, right: np.ndarray, cam: StereoCamera,
                stamp_ns: int | None = None,
                motion: tuple | Callable[[], tuple | None] | None = None,
                up: np.ndarray | None = None) -> GpodResult:
        """One stereo pair: arguments and result as `GpodDetector.process`; with the map
        enabled, the result's ``obstacles`` are those the map confirms
        (`objects_to_obstacles`), or the detector's own while the map has placed fewer
        than ``min_placed_pairs`` pairs in a row (it needs the camera motion while the
        rig moves: without it the map is cleared): at a start as they are (for
        ``start_raw_s``), after a clear or a start the map did not take over from
        those chained over pairs (`core.moving_reports.ChainedReports`); and
        ``timings_ms['map']`` is the map's time, ms (included in 'total'). With a
        ``motion_predictor`` the map's motion is its prediction for ``stamp_ns`` (the
        identity while the detector finds the rig still), whatever ``motion`` is."""
        got: list = []
        if callable(motion):
            fn = motion

            def motion():      # the same callable, its answer kept
                m = fn()
                got.append(m)
                return m
        else:
            got.append(motion)
        predicted: list = []
        predictor = self.motion_predictor if self.map is not None else None

        def predict(still: bool):
            # the predictor's motion for this pair, asked once (it keeps the pose given)
            if not predicted:
                predicted.append(predictor.predict(stamp_ns, still=bool(still))
                                 if predictor is not None and stamp_ns is not None
                                 else None)
            return predicted[0]

        # the ground surface is carried by the map's motion (`core.surface_tracking`)
        self.detector.surface_motion = predict if predictor is not None else None
        result = self.detector.process(left, right, cam, stamp_ns=stamp_ns, motion=motion,
                                       up=up)
        if self.map is None:
            return result
        t0 = time.perf_counter()
        m = got[-1] if got else None
        if predictor is not None:
            m = predict(bool(result.still))
        stamp_s = (stamp_ns * 1e-9 if stamp_ns is not None
                   else result.frame_index * self.gpod_config.tracks.frame_period_s)
        plane = result.metric_plane if result.status == 'tracking' else None
        # the start: start_raw_s from the first pair with a plane
        if plane is not None and self._first_plane_s is None:
            self._first_plane_s = stamp_s
        if (self._first_plane_s is not None
                and stamp_s - self._first_plane_s > self.map_config.start_raw_s):
            self.past_start = True
        # a plane carried over a pair whose refit failed is last pair's ground: while the
        # rig moves the camera has pitched since (the gait: a few degrees a pair), and
        # heights against it are off by that times the range; of such a pair's evidence
        # only what `carried_plane_evidence` names is entered (by default its ground seen
        # free); the map still moves and reports what it holds
        carried = not (result.plane_updated or bool(result.still))
        enter = self.map_config.carried_plane_evidence if carried else 'all'
        ev = (self.evidence(result, cam, ground_only=enter == 'ground')
              if plane is not None and enter != 'none' else None)
        objects = self.map.update(stamp_s, plane, ev, m, result.still, cam)
        arrays = report_arrays(result.obstacles)
        passing = self.tall.passing(stamp_s, *arrays)
        chained = self.unmapped.passing(stamp_s, *arrays,
                                        np.array([o.width for o in result.obstacles], float))
        if self.map.placed_pairs < self.map_config.min_placed_pairs:
            # the map has not seen enough pairs in a row to confirm anything: at a start
            # the detector's reports go out as they are (for start_raw_s); once the map
            # had confirmed and was then cleared (the camera's motion unknown while
            # walking), or never took over, only those seen in a chain of pairs
            # (`core.moving_reports.ChainedReports`)
            obstacles = (tuple(o for o, ok in zip(result.obstacles, chained) if ok)
                         if self.past_start else result.obstacles)
        else:
            obstacles = (tuple(objects_to_obstacles(
                objects, cam, plane, result.obstacles, self.map_config.attach_m,
                self.map_config.corridor_half_width_m, self._seen_ground(stamp_s),
                self.map_config.span))
                         if plane is not None else ())
            # the detector's unknown ahead (height NaN, `core.unseen_ground`) is no
            # evidence for the map, and goes out as it is; so does a tall report the map
            # did not confirm (`core.moving_reports`: a passer-by)
            taken = [o.position for o in obstacles]
            obstacles += tuple(o for o, ok in zip(result.obstacles, passing)
                               if np.isnan(o.height) or (ok and not any(
                                   np.array_equal(o.position, p) for p in taken)))
        self.past_start |= self.map.placed_pairs >= self.map_config.min_placed_pairs
        ms = (time.perf_counter() - t0) * 1e3
        timings = dict(result.timings_ms)
        timings['map'] = ms
        timings['total'] = timings.get('total', 0.0) + ms
        return dataclasses.replace(result, obstacles=obstacles, timings_ms=timings)

    def _seen_ground(self, stamp_s: float) -> Callable[[np.ndarray], np.ndarray] | None:
        """Whether the map saw ground at detector reports' feet and around them lately
        ((M, 2) feet in G -> (M,) bool, `EvidenceMap.ground_seen_around` within
        ``attach_seen_ground_s``), for `objects_to_obstacles`; None when that is off."""
        within, emap = self.map_config.attach_seen_ground_s, self.map
        if within <= 0 or emap is None:
            return None
        return lambda xy: emap.ground_seen_around(xy, stamp_s, within)

    def evidence(self, result: GpodResult, cam: StereoCamera, ground_only: bool = False):
        """The pair's matched edge pixels as map evidence (`pair_evidence`): the
        detector's counted obstacle pixels raised, its drop pixels drop, the pixels on
        the plane within their threshold (on no obstacle or drop string) ground; σ_d the
        pixel's threshold over ``threshold.k``; each weighed 1 - c, c the share of its
        rivals that say otherwise in its and its rivals' support
        (`GpodFeatures.contrary_rival_share`): the chance that it is not the ground matched
        wrongly, were the supports likelihoods. Where the ground surface ends at a step
        of the ground across the path (`core.map_steps.ground_step`, rule_ground_step),
        the step enters as raised (drop) evidence just beyond it, at its height
        (`core.map_steps.with_step`; a drop's with ``min_drop_pixels`` points a
        place), and its far side's ground pixels as none. ``ground_only``: the ground
        pixels alone (the raised and drop ones, and any step, enter nothing)."""
        f = result.features
        k = len(f)
        thr = (np.asarray(f.threshold, float) if f.threshold is not None
               else np.full(k, float(result.threshold_px)))
        tk = self.gpod_config.threshold.k
        sigma_d = thr / tk if self.gpod_config.threshold.mode == 'sigma' else np.full(
            k, float(result.sigma_px) if math.isfinite(result.sigma_px)
            else self.map_config.default_sigma_px)
        ex = f.excess_mean if f.excess_mean is not None else f.excess
        kind = np.full(k, NONE, np.int8)
        ground = np.isfinite(ex) & (np.abs(ex) <= thr) & (f.string_class == 0)
        kind[ground] = GROUND
        kind[f.is_drop] = NONE if ground_only else DROP
        kind[f.is_obstacle] = NONE if ground_only else RAISED
        u = 0.5 * (np.asarray(f.u_left, float) + np.asarray(f.u_right, float))
        assert result.metric_plane is not None         # evidence of a tracked ground only
        weight = (1.0 - np.asarray(f.contrary_rival_share, float)
                  if f.contrary_rival_share is not None and self.map_config.weigh_by_rivals
                  else None)
        # rule_ground_step: a step of the ground across the corridor, supported by
        # pixels each under the threshold (the ground pixels: what stands out is the
        # pixel test's)
        step = None
        if not ground_only and may_step(result.surface, self.map_config.steps):
            on_ground = flat_nonzero(kind == GROUND)
            step = ground_step(result.surface, cam.triangulate(u[on_ground], f.v[on_ground],
                                                               f.d[on_ground]),
                               self.map_config.steps)
        if step is not None:
            # its far side is ground, but not the ground the plane is: not seen free
            kind[on_ground[step.far]] = NONE
        ev = pair_evidence(cam, result.metric_plane, u, f.v, f.d, sigma_d, kind,
                           self.map_config.max_range_m, weight)
        if step is None:
            return ev
        # the step is raised (a step up) or drop evidence just beyond it
        mc = self.map_config
        return with_step(ev, step, mc.steps, mc.cell_m, mc.min_drop_pixels)
