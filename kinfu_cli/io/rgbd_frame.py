"""A depth frame as the readers give it (RGBDFrame), and the count of the frames read, skipped and dropped by
reason (FrameStats) with the warnings those counts call for: what io.frames' readers produce and fusion reports."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinfu_cli.io.messages import header_stamp_ns

DROP_NO_POSE = "no camera pose within the TF range"
DROP_CHAIN_BROKEN = "no TF chain to the camera at that time"  # inside the TF's time, no chain with transforms there
DROP_NO_POSE_TOPIC = "no pose message within tolerance"
DROP_EMPTY = "depth image has no valid pixel"
DROP_NO_PIXELS = "depth image is empty (0 pixels wide or high)"
DROP_NO_COLOR = "no colour image within tolerance"


@dataclass
class RGBDFrame:
    """One depth frame. index: position of the depth message on its topic among those read (0-based;
    counted from the start of the time window minus the tolerance when start_s is given)."""

    index: int
    stamp_ns: int
    depth: np.ndarray  # float32 (H, W) metres, 0 = invalid
    color: np.ndarray | None  # uint8 (H, W, 3) RGB, or None
    K: np.ndarray  # (3, 3) of the depth camera
    T_world_camera: np.ndarray | None  # (4, 4) camera-to-world, or None with pose_source="none"
    color_mask: np.ndarray | None = None  # bool (H, W): False where colour has no sample (projected colour)


# the share of a run's frames that may lack a colour image within the tolerance before a warning (the first and
# last frames often do: the colour stream starts and stops at other times)
UNPAIRED_COLOR_WARN = 0.10
# how long (log time) colour images are kept for depth messages still to come: a depth driver's processing and
# the recorder's queue log depth images after the colour images of the same instant (some 30-300 ms)
COLOR_LOOKAHEAD_NS = 1_000_000_000
MAX_16BIT_MM = 65535  # the largest depth a 16-bit millimetre image holds (65535 itself reads as no measurement)


@dataclass
class FrameStats:
    """How many depth frames were used, skipped (every n-th, time window) and dropped (reason -> count)."""

    depth_messages: int = 0
    used: int = 0
    skipped: int = 0
    without_color: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    color_registration: dict | None = None  # ColorRegistration.as_dict() when there is a colour topic
    notes: list[str] = field(default_factory=list)  # what was assumed to read the frames (a warning each)
    depth_units: float | None = None  # m per unit of 16-bit depth when not mm (a RealSense SDK recording's)
    # frames used without colour although the colour topic could be placed: no colour image within the tolerance;
    # the nearest one's distance in time (None when there was none at all) and the tolerance
    color_unpaired: int = 0
    color_nearest_ns: int | None = None
    tolerance_ns: int = 0
    # depth images whose stamp is equal to or earlier than the one before (kept: said in a warning); the first one
    stamps_not_increasing: int = 0
    first_not_increasing_ns: int | None = None
    # 32FC1 depth pixels beyond what a 16-bit millimetre image holds (65.535 m: millimetres stored as metres?)
    pixels_over_16bit_mm: int = 0
    frames_over_16bit_mm: int = 0
    # depth frames logged so long after their stamp that colour images near it were no longer kept
    color_cut_short: int = 0
    # colour images whose stamp is earlier than the one before (a colour clock that went back); the first one, how
    # far back it went, and the colour topic
    color_stamps_backwards: int = 0
    first_color_backwards_ns: int | None = None
    color_backwards_ns: int = 0
    color_topic: str | None = None
    # colour images paired with a depth frame that hold no pixel (0 wide or high): the frame goes without colour
    color_empty: int = 0

    def drop(self, reason: str) -> None:
        self.dropped[reason] = self.dropped.get(reason, 0) + 1

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def warnings(self, recording: str) -> list[str]:
        """What reading the frames assumed (notes), and why frames of a recording with a colour topic carry no
        colour (io.color_registration could not place it): one warning each, for every command that reads
        frames."""
        out = [f"{recording}: {n}" for n in self.notes]
        reg = self.color_registration
        if reg and reg["mode"] == "none":
            out.append(f"{recording}: frames without colour: {reg['reason']}, so the colour images cannot be placed "
                       f"on the depth (resizing them would paint each surface with its neighbour's)")
        if self.color_stamps_backwards:
            out.append(f"{recording}: {self.color_stamps_backwards} colour images on {self.color_topic} have a stamp "
                       f"earlier than the one before (the first at {self.first_color_backwards_ns} ns, "
                       f"{self.color_backwards_ns / 1e6:.0f} ms back): the colour clock went back (a driver "
                       f"restart?); a depth frame takes colour only from the images before such a step back, or, when "
                       f"its own stamps went back too, after it, so frames may be left without colour")
        if self.color_unpaired > UNPAIRED_COLOR_WARN * max(self.used, 1):  # a few at the ends are usual
            near = ("no colour image at all in the frames' time window" if self.color_nearest_ns is None else
                    f"the nearest colour image {self.color_nearest_ns / 1e6:.0f} ms from a depth frame, over "
                    f"the {self.tolerance_ns / 1e6:.0f} ms tolerance")
            why = ("the colour stamps went back: see the warning before" if self.color_stamps_backwards else
                   "a larger tolerance pairs images further apart in time")
            out.append(f"{recording}: {self.color_unpaired} of {self.used} frames have no colour ({near}); their "
                       f"surfaces stay uncoloured ({why})")
        if self.color_cut_short:
            out.append(f"{recording}: {self.color_cut_short} depth frames were logged more than "
                       f"{COLOR_LOOKAHEAD_NS / 1e9:g} s after colour images within the tolerance of their stamp, "
                       f"which were no longer kept: these frames may carry a colour image farther in time than the "
                       f"nearest, or none")
        if self.color_empty:
            out.append(f"{recording}: {self.color_empty} colour images on {self.color_topic} paired with depth frames "
                       f"are empty (0 pixels wide or high: a driver fault?); those frames carry no colour")
        if self.dropped.get(DROP_NO_PIXELS):
            out.append(f"{recording}: {self.dropped[DROP_NO_PIXELS]} of {self.depth_messages} depth images are empty "
                       f"(0 pixels wide or high: a driver fault?); they were left out")
        if self.stamps_not_increasing:
            out.append(f"{recording}: {self.stamps_not_increasing} of {self.depth_messages} depth images have a "
                       f"stamp equal to or earlier than the one before (the first at {self.first_not_increasing_ns} "
                       f"ns): repeated or backward stamps (a driver or clock fault?); they are used at the stamps "
                       f"they carry")
        if self.pixels_over_16bit_mm:
            out.append(f"{recording}: {self.pixels_over_16bit_mm} depth pixels in {self.frames_over_16bit_mm} "
                       f"frames read {MAX_16BIT_MM / 1000:g} m or more (32FC1 depth is in metres: millimetres "
                       f"stored as metres?); a 16-bit millimetre depth image (kinfu export) cannot hold them and "
                       f"writes them as no measurement (65535)")
        return out

    def as_dict(self) -> dict:
        return {"depth_messages": self.depth_messages, "used": self.used, "skipped": self.skipped,
                "without_color": self.without_color, "dropped": dict(self.dropped),
                "dropped_total": self.dropped_total,
                **({"color_registration": self.color_registration} if self.color_registration else {}),
                **({"notes": list(self.notes)} if self.notes else {}),
                **({"depth_units_m": self.depth_units} if self.depth_units is not None else {}),
                **({"stamps_not_increasing": self.stamps_not_increasing} if self.stamps_not_increasing else {}),
                **({"color_cut_short": self.color_cut_short} if self.color_cut_short else {}),
                **({"color_stamps_backwards": self.color_stamps_backwards} if self.color_stamps_backwards else {}),
                **({"pixels_over_16bit_mm": self.pixels_over_16bit_mm} if self.pixels_over_16bit_mm else {}),
                **({"color_empty": self.color_empty} if self.color_empty else {})}


def message_stamp_ns(msg: object, log_ns: int) -> int:
    """A message's header stamp (ns), or its log time where the header has none (a zero stamp)."""
    s = header_stamp_ns(msg)
    return s if s is not None else int(log_ns)
