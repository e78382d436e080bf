"""Pairing by stamp: each depth image with the nearest colour image within the tolerance, the camera info of its
own stamp and its camera pose, streaming the topics once in log order (FramePairer, what io.frames.iter_frames
runs). Only the messages that may still be a partner are held (about a second of them), so memory does not grow
with the recording."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from kinfu_cli.core.camera import scaled_intrinsics
from kinfu_cli.core.errors import RecordingError
from kinfu_cli.io.camera_info import image_camera, is_rectified_topic
from kinfu_cli.io.color_registration import (ColorRegistration, ColorSizeError, color_size_reason, colour_camera_of,
                                             register_color)
from kinfu_cli.io.messages import decode_color, decode_depth
from kinfu_cli.io.pointcloud2 import decode_cloud
from kinfu_cli.io.rgbd_frame import (COLOR_LOOKAHEAD_NS, DROP_EMPTY, DROP_NO_COLOR, DROP_NO_PIXELS, MAX_16BIT_MM,
                                     FrameStats, RGBDFrame, message_stamp_ns)
from kinfu_cli.io.roles import Roles
from kinfu_cli.io.undistort import Undistorter, reproject_pinhole

# a camera pose (4x4 camera-to-world) at a depth stamp (ns), None where there is none
PoseLookup = Callable[[int], "np.ndarray | None"]


@dataclass(frozen=True)
class _Camera:
    """A depth camera as one camera info gives it: intrinsics, image size, roi / binning note, lens; and, for a
    rectified colour topic in its frame, the pinhole camera (P) its colour images are already on."""

    K: np.ndarray
    width: int
    height: int
    reduction: str
    lens: Undistorter
    color_K: np.ndarray | None = None


@dataclass
class _Waiting:
    """A depth message waiting for its colour partner and for the camera info of its stamp."""

    index: int
    stamp: int
    msg: object
    cam: _Camera  # the camera info of its stamp, or (until that comes) the latest one read before it
    info_until: int | None  # log ns until which the camera info of its stamp may come; None: `cam` is settled
    color_pass: int  # which run of the colour stream's increasing stamps it may take colour from


class FramePairer:
    """Streams the depth, colour and camera-info topics once, in log order, pairing each depth image by stamp with
    the nearest colour image within the tolerance, the camera info of its stamp and its camera pose. Only the
    messages still waiting for a partner are kept: depth frames until no closer colour image can arrive and their
    camera info came (or cannot come), colour images (undecoded) for COLOR_LOOKAHEAD_NS of log time (depth is often
    logged later than the colour of the same instant, and not always in stamp order) or while a waiting frame can
    use them, camera infos for COLOR_LOOKAHEAD_NS; frames that lost a partner to that bound are counted
    (color_cut_short). Colour stamps that go back (a driver restart) start a new pass of colour images: a depth
    frame takes colour of the pass of its time only (its stamps go back too to reach the new one)."""

    def __init__(self, rec, roles: Roles, depth_topic: str, K: np.ndarray, width: int, height: int,
                 pose_fn: PoseLookup | None, tol_ns: int, stats: FrameStats, require_color: bool,
                 registration: ColorRegistration | None = None, lens: Undistorter | None = None,
                 cloud: bool = False, depth_units: float | None = None, reduction: str = "",
                 color_info_topic: str | None = None) -> None:
        self.rec = rec
        # 16-bit depth in these units (m) instead of mm: a factor on decode_depth's mm reading
        self.unit_factor = None if depth_units is None else np.float32(depth_units / 0.001)
        self.cloud = cloud  # depth (and colour, with an rgb field) from an organized PointCloud2
        self.registration = registration
        self.depth_topic = depth_topic
        self.info_topic = roles.info_topic
        self.color_topic = roles.color_topic
        # the projected colour camera's info topic: the registration takes each one's camera (not the SDK's)
        self.color_info_topic = color_info_topic if color_info_topic != self.info_topic else None
        # (stamp, log ns, registration with its camera) of the colour camera infos read within the look-ahead
        self.color_infos: deque[tuple[int, int, ColorRegistration]] = deque()
        # the latest camera info read (the first one's, with its lens, until the stream reads one): K, size, roi /
        # binning of the calibrated sensor ("" when none: image_camera)
        first_info = rec.first_message(self.info_topic) if self._rectified_color() else None
        self.camera = _Camera(K, width, height, reduction, lens if lens is not None else Undistorter.pinhole(K),
                              None if first_info is None else self._color_K(first_info))
        self.infos: deque[tuple[int, int, _Camera]] = deque()  # (stamp, log ns, camera) read within the look-ahead
        self.pose_fn = pose_fn
        self.tol_ns = tol_ns
        self.stats = stats
        self.require_color = require_color
        self.pending: deque[_Waiting] = deque()
        # (stamp, log ns, colour msg, pass, the registration when it was read), decoded when paired
        self.colors: deque[tuple[int, int, object, int, ColorRegistration | None]] = deque()
        self.depth_stamp: int | None = None  # of the latest depth message read: later ones should not be earlier
        self.color_stamp: int | None = None  # of the latest colour message read
        self.color_pass = 0  # colour stamps that went back by more than the tolerance so far
        self.depth_pass = 0  # the colour pass the depth messages read now take colour from
        self.depth_back: tuple[int, int] | None = None  # (log ns, index) of the latest depth stamp that went back
        # stamps of the colour images dropped by the look-ahead, as [first, last] runs without a gap over twice the
        # tolerance: a depth stamp within the tolerance of a run had a colour image that near
        self.dropped_colors: deque[list[int]] = deque()

    def stream(self, start_ns: int | None, end_ns: int | None, every: int) -> Iterator[RGBDFrame]:
        """Frames of depth messages recorded (log time) in [start_ns, end_ns] (either None: open), every n-th;
        messages within the tolerance outside the window are read too, as partners."""
        tol_ns, stats, pending = self.tol_ns, self.stats, self.pending
        read_start = None if start_ns is None else max(0, start_ns - tol_ns)
        # colour and camera infos logged up to the look-ahead earlier may be the partners of a depth message
        look_start = None if start_ns is None else max(0, start_ns - tol_ns - COLOR_LOOKAHEAD_NS)
        read_end = None if end_ns is None else end_ns + tol_ns
        # and those logged up to the look-ahead later may be the partners of the last depth messages
        look_end = None if end_ns is None else read_end + COLOR_LOOKAHEAD_NS
        partners = [t for t in (self.info_topic, self.color_topic, self.color_info_topic) if t]
        index = 0  # position of the depth message on its topic among those read
        kept = 0  # depth messages inside the window so far
        last_stamp = None  # of the previous depth message inside the window
        for topic, log_ns, msg in self.rec.messages([self.depth_topic] + partners,
                                                    start_ns=look_start if partners else read_start,
                                                    end_ns=look_end if partners else read_end):
            if pending and pending[0].info_until is not None and pending[0].info_until < log_ns:
                self._settle(lambda w: w.info_until < log_ns)  # no camera info of their stamps came in time
                yield from self._flush_ready()
            if read_end is not None and log_ns > read_end:  # read for the partners' look-ahead only
                if not pending:
                    break  # no frame waits for a partner
                if topic == self.depth_topic:
                    continue  # depth after the window is not the window's
            if topic == self.info_topic:
                self._read_info(msg, log_ns)
                yield from self._flush_ready()
                continue
            if topic == self.color_info_topic:
                self._read_color_info(msg, log_ns)
                continue
            stamp = message_stamp_ns(msg, log_ns)
            if topic == self.color_topic:
                self._read_color(stamp, log_ns, msg)
                yield from self._flush(stamp)
                self._forget_colors(log_ns)
                continue
            if read_start is not None and log_ns < read_start:
                continue  # before the tolerance margin: read for the partners' look-ahead only
            # a depth message: the window is in the recording's time (log time, as `rosbag play --start` and the
            # recording's start use), not the header's, whose clock may be another (a device's, simulated time)
            index += 1
            if self.depth_stamp is not None and stamp < self.depth_stamp:
                self.depth_pass = self.color_pass  # its clock went back too: the colour's latest pass is its own
                self.depth_back = (log_ns, index - 1)
            self.depth_stamp = stamp
            if (start_ns is not None and log_ns < start_ns) or (end_ns is not None and log_ns > end_ns):
                continue  # read only for the tolerance margin of the time window
            stats.depth_messages += 1
            if last_stamp is not None and stamp <= last_stamp:
                stats.stamps_not_increasing += 1
                if stats.first_not_increasing_ns is None:
                    stats.first_not_increasing_ns = stamp
            last_stamp = stamp
            kept += 1
            if (kept - 1) % every:
                stats.skipped += 1
                continue
            cam = self._info_of(stamp)  # the camera info of its stamp when it came first; else it may come next
            pending.append(_Waiting(index - 1, stamp, msg, cam or self.camera,
                                    None if cam is not None or self.info_topic is None else log_ns + COLOR_LOOKAHEAD_NS,
                                    self.depth_pass))
            if self.color_topic is None:
                yield from self._flush(None)
            elif len(pending) > 64:  # colour stream stalled: do not hold depth frames forever
                frame = self._emit(pending.popleft())
                if frame is not None:
                    yield frame
        yield from self._flush(None, settled_only=False)

    def _rectified_color(self) -> bool:
        """Whether colour images are the depth camera's own pixels on a rectified topic (already undistorted onto
        the camera info's P: not to be undistorted again)."""
        return bool(self.info_topic) and self.registration_mode() == "same-frame" and is_rectified_topic(
            self.color_topic)

    def _color_K(self, msg: object) -> np.ndarray | None:
        """The pinhole camera of a rectified colour topic by camera info `msg` (P, its roi and binning); None when
        its P cannot be read (the colour is then taken as on K)."""
        try:
            return image_camera(msg, f"{self.rec.path}: {self.info_topic}", self.color_topic).K
        except RecordingError:
            return None

    def _read_info(self, msg: object, log_ns: int) -> None:
        """Take a camera info: the latest one from now, and the one of the waiting frames of its stamp; the frames
        before its stamp keep theirs (no info of their own stamp comes after a later one)."""
        info = image_camera(msg, f"{self.rec.path}: {self.info_topic}", self.depth_topic)
        lens = self.camera.lens
        if not (lens.model == info.model and np.array_equal(lens.D, info.D) and np.array_equal(lens.K, info.K)):
            lens = Undistorter(info.K, info.model, info.D)
        self.camera = _Camera(info.K, info.width, info.height, info.reduction, lens,
                              self._color_K(msg) if self._rectified_color() else None)
        stamp = message_stamp_ns(msg, log_ns)
        self.infos.append((stamp, log_ns, self.camera))
        while self.infos[0][1] < log_ns - COLOR_LOOKAHEAD_NS:
            self.infos.popleft()
        for w in self.pending:
            if w.info_until is not None and w.stamp == stamp:
                w.cam = self.camera
        self._settle(lambda w: w.stamp <= stamp)

    def _info_of(self, stamp: int) -> _Camera | None:
        """The camera of the latest camera info read with this stamp (None when none is kept)."""
        return next((cam for s, _, cam in reversed(self.infos) if s == stamp), None)

    def _settle(self, done: Callable[[_Waiting], bool]) -> None:
        """Waiting frames for which `done` says their camera info is the one they hold."""
        for w in self.pending:
            if w.info_until is not None and done(w):
                w.info_until = None

    def _read_color(self, stamp: int, log_ns: int, msg: object) -> None:
        """Keep a colour image; a stamp before the one before is counted, and when it goes back by more than the
        tolerance a new pass of colour images begins (the waiting frames are of the one before)."""
        stats = self.stats
        if self.color_stamp is not None and stamp < self.color_stamp:
            stats.color_stamps_backwards += 1
            if stats.first_color_backwards_ns is None:
                stats.first_color_backwards_ns, stats.color_backwards_ns = stamp, self.color_stamp - stamp
                stats.color_topic = self.color_topic
            if self.color_stamp - stamp > self.tol_ns:
                self.color_pass += 1
                self.dropped_colors.clear()  # stamps of the other clock: no frame of this pass lost them
                if self.depth_back is not None and self.depth_back[0] >= log_ns - COLOR_LOOKAHEAD_NS:
                    self.depth_pass = self.color_pass  # the depth clock went back just before: the same restart
                    for w in self.pending:
                        if w.index >= self.depth_back[1]:
                            w.color_pass = self.color_pass
        self.color_stamp = stamp
        self.colors.append((stamp, log_ns, msg, self.color_pass, self.registration))

    def _read_color_info(self, msg: object, log_ns: int) -> None:
        """Take a colour camera info: the colour images of its stamp, and those after it, are projected with its
        camera (a re-calibration or a resolution change mid-stream); one that cannot be read is said, and the one
        before it kept."""
        if self.registration is None or self.registration.mode != "project":
            return
        where = f"{self.rec.path}: {self.color_info_topic}"
        try:
            lens, size = colour_camera_of(msg, where, image_topic=self.color_topic)
        except RecordingError as exc:
            note = f"{exc}; the colour images of its time are projected with the camera info before it"
            self.stats.notes += [note] if note not in self.stats.notes else []
            return
        reg = self.registration
        if not (size == reg.color_size and lens.model == reg.lens.model and np.array_equal(lens.K, reg.lens.K)
                and np.array_equal(lens.D, reg.lens.D)):
            self.registration = replace(reg, lens=lens, color_size=size)
        self.color_infos.append((message_stamp_ns(msg, log_ns), log_ns, self.registration))
        while self.color_infos[0][1] < log_ns - COLOR_LOOKAHEAD_NS:
            self.color_infos.popleft()

    def _color_camera(self, stamp: int, read_with: ColorRegistration) -> ColorRegistration:
        """The registration of the colour image of `stamp`: with the colour camera info of its stamp when one is
        kept, else `read_with` (the one when the image was read)."""
        return next((reg for s, _, reg in reversed(self.color_infos) if s == stamp), read_with)

    def _emit(self, waiting: _Waiting) -> RGBDFrame | None:
        """The frame of one depth message seen by its camera (the camera info of its stamp: a frame waits for its
        colour partner, and a later camera info may come meanwhile), or None (counted in stats) when it has no
        pose, no valid pixel, or no colour while colour is required."""
        index, stamp, msg, cam = waiting.index, waiting.stamp, waiting.msg, waiting.cam
        cloud_color = None
        if self.cloud:
            depth, cloud_color = decode_cloud(msg, f"{self.rec.path}: depth topic {self.depth_topic}")
        else:
            depth = decode_depth(msg, f"{self.rec.path}: {self.depth_topic}")
            if depth.size == 0:  # no image at all, not one without readings: its size would scale K to zeros
                self.stats.drop(DROP_NO_PIXELS)
                return None
            if self.unit_factor is not None and str(getattr(msg, "encoding", "")) in ("16UC1", "mono16"):
                depth *= self.unit_factor
        over = int(np.count_nonzero(depth >= np.float32((MAX_16BIT_MM - 0.5) / 1000)))
        if over:  # millimetres rounded to 65535 or more: "no measurement" in a 16-bit image (kinfu export)
            self.stats.pixels_over_16bit_mm += over
            self.stats.frames_over_16bit_mm += 1
        h, w = depth.shape
        K = cam.K
        if cam.width and cam.height and (w, h) != (cam.width, cam.height):
            K = self._scaled_K(w, h, cam)
        depth = cam.lens.image(depth)
        T = None
        if self.pose_fn is not None:
            T = self.pose_fn(stamp)
            if T is None:
                return None
        if not np.any(depth > 0):
            self.stats.drop(DROP_EMPTY)
            return None
        color = color_mask = None
        unpaired = False
        if self.color_topic is None and cloud_color is not None:
            color = cloud_color  # registered: the same pixels
        elif self.color_topic is not None and self.registration_mode() != "none":
            own = [c for c in self.colors if c[3] == waiting.color_pass]  # not another pass's, of another clock
            best_stamp, _, best, _, read_with = min(own, key=lambda c: abs(c[0] - stamp)) if own else (None,) * 5
            if self._lost_nearer_color(stamp, best_stamp):
                self.stats.color_cut_short += 1
            if best_stamp is not None and abs(best_stamp - stamp) > self.tol_ns:
                gap, seen = abs(best_stamp - stamp), self.stats.color_nearest_ns
                self.stats.color_nearest_ns = gap if seen is None else min(seen, gap)
            unpaired = best_stamp is None or abs(best_stamp - stamp) > self.tol_ns
            if not unpaired:
                where = f"{self.rec.path}: {self.color_topic}"
                color = decode_color(best, where)
                if color.size == 0:  # no image at all: as if unpaired, said in a warning
                    self.stats.color_empty += 1
                    self.stats.color_topic = self.color_topic
                    color = None
                elif self.registration_mode() == "project":
                    try:
                        reg = self._color_camera(best_stamp, read_with)
                        color, color_mask = register_color(reg, depth, K, color, where)
                    except ColorSizeError:  # the images changed size mid-run: no colour from here on
                        self._lose_color(color.shape[1::-1], index)
                        color = color_mask = None
                elif cam.color_K is not None:  # a rectified topic: undistorted already, onto P
                    color = reproject_pinhole(color, cam.color_K, cam.K, (cam.width, cam.height))
                elif not self._rectified_color():  # the depth camera's own pixels: its lens too
                    color = cam.lens.image(color, size_of_K=(cam.width, cam.height))
        if color is None:
            if self.require_color:
                self.stats.drop(DROP_NO_COLOR)
                return None
            self.stats.without_color += 1
            self.stats.color_unpaired += unpaired
        self.stats.used += 1
        return RGBDFrame(index=index, stamp_ns=stamp, depth=depth, color=color, K=K.copy(), T_world_camera=T,
                         color_mask=color_mask)

    def _lost_nearer_color(self, stamp: int, best_stamp: int | None) -> bool:
        """Whether a colour image dropped by the look-ahead was within the tolerance of `stamp` and nearer than
        `best_stamp` (the nearest kept one, None for none): a farther neighbour lost costs the frame nothing. A run's
        ends are dropped stamps; inside a run, where its images lie is not kept, so a nearer one is assumed."""
        reach = self.tol_ns if best_stamp is None else min(self.tol_ns, abs(best_stamp - stamp) - 1)
        return reach >= 0 and any(first - reach <= stamp <= last + reach for first, last in self.dropped_colors)

    def registration_mode(self) -> str:
        """How colour images map onto the depth: "same-frame", "project" or "none" (left out)."""
        return "same-frame" if self.registration is None else self.registration.mode

    def _lose_color(self, size: tuple[int, int], index: int) -> None:
        """Colour images that stopped fitting their camera info (register_color could place none): the colour is
        left out from depth frame `index` on, with the reason in stats (the warning of FrameStats.warnings)."""
        reason = f"{color_size_reason(self.color_topic, size, self.registration)} from depth frame {index} on"
        self.registration = replace(self.registration, mode="none", reason=reason)
        self.stats.color_registration = self.registration.as_dict()

    def _scaled_K(self, w: int, h: int, cam: _Camera) -> np.ndarray:
        """K for depth images of w x h whose camera info is for another size with the same aspect ratio (a
        decimation filter, image_proc's resize), said once in stats.notes; RecordingError otherwise, and when the
        camera info's roi / binning say which part of the sensor the images are."""
        sx, sy = w / cam.width, h / cam.height
        said = f"camera info {self.info_topic}" if self.info_topic else "the first depth image"
        if abs(sx - sy) > 0.01 * max(sx, sy) or not self.info_topic or cam.lens or cam.reduction:
            reduced = f" ({cam.reduction})" if cam.reduction else ""
            raise RecordingError(f"{self.rec.path}: depth image on {self.depth_topic} is {w}x{h} but {said} "
                                 f"says {cam.width}x{cam.height}{reduced}")
        K = scaled_intrinsics(cam.K, (sx, sy))
        note = (f"depth images on {self.depth_topic} are {w}x{h} but {said} says {cam.width}x{cam.height}: "
                f"its intrinsics were scaled by {sx:.4g}")
        if note not in self.stats.notes:
            self.stats.notes.append(note)
        return K

    def _forget_colors(self, log_ns: int) -> None:
        """Forget colour images logged over COLOR_LOOKAHEAD_NS ago that no waiting frame can use (a depth message
        that still wants one comes too late: counted when it does). Not by the latest depth stamp: a depth image
        logged after a later-stamped one wants the colour of its own."""
        waiting = min((w.stamp for w in self.pending), default=None)
        bounds = [s for s in (waiting, self.depth_stamp) if s is not None]
        runs, gap = self.dropped_colors, 2 * self.tol_ns
        while bounds and runs and runs[0][1] < min(bounds) - self.tol_ns:
            runs.popleft()
        while self.colors and self.colors[0][1] < log_ns - COLOR_LOOKAHEAD_NS and (
                waiting is None or self.colors[0][0] < waiting - self.tol_ns):
            stamp, _, _, color_pass, _ = self.colors.popleft()
            if color_pass != self.color_pass:
                continue  # of another clock: no frame to come lost it
            if runs and runs[-1][0] - gap <= stamp <= runs[-1][1] + gap:
                runs[-1] = [min(runs[-1][0], stamp), max(runs[-1][1], stamp)]
            else:
                runs.append([stamp, stamp])

    def _flush(self, up_to: int | None, settled_only: bool = True) -> Iterator[RGBDFrame]:
        """Emit waiting depth frames, in log order, whose colour partner can no longer arrive (all when up_to is
        None; those of an earlier colour pass too) and, unless not settled_only, whose camera info is settled."""
        pending = self.pending
        while pending and (pending[0].info_until is None or not settled_only) and (
                up_to is None or pending[0].stamp + self.tol_ns < up_to or pending[0].color_pass != self.color_pass):
            frame = self._emit(pending.popleft())
            if frame is not None:
                yield frame

    def _flush_ready(self) -> Iterator[RGBDFrame]:
        """Emit the waiting frames that a settled camera info made ready: without colour; with colour, the next
        colour image says (a depth clock that went back may be followed by the colour's)."""
        if self.color_topic is None:
            yield from self._flush(None)
