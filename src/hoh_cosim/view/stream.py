"""The view in Rerun: a recording stream to a web viewer on this machine, to a .rrd file, or both.

    world                   the base frame B, z up
    world/workspace         the controller's workspace box
    world/surface           the phantom's or the abdomen's surface, moved by the breath
    world/arm/base, link1-6 the UR5: each link's frame in B, its DH link and joint housing
    world/probe             the TCP frame in B with the tool: FT-150, housing, probe, handle
    world/probe/tip         the tip
    world/forces/hand       the hand's force at the handle (1 cm per N)
    world/forces/contact    the surface's force on the tip (1 cm per N)
    world/command/twist     the commanded linear velocity at the tip (1 cm per 10 mm/s)
    world/command/replayed  a replay's recomputed one beside it
    world/fixture           the virtual fixture's plane at the tip while it is engaged
    world/path/reference    where the path wants the tip
    plots/hand_force        the hand's force x, y, z (and the estimator's, in a run) [N]
    plots/contact_force     |contact force| with the soft cap and the stop [N]
    plots/tip_speed         |tip velocity| with the speed limit [mm/s]
    plots/path_error        |tip - reference| [mm]
    plots/command           the commanded linear velocity x, y, z (and the replayed) [mm/s]
    log/controller          the mode's and the status bits' transitions, the session's events

Time is the run's simulation time (`sim_time`) or the session's (`session_time`), so a 30 s run
can be scrubbed. Tracks arrive in blocks (`ViewStream.log`) and go out as columns
(`send_columns`): one call per entity and block, not one per instant.

Live, the data go to a gRPC server on a free loopback port and Rerun's web viewer (it ships in the
wheel) is served on `web_port` (all interfaces: Rerun's own choice) pointed at it; the address is
`ViewStream.url`. A recording is written by a stream of its own (same recording id) to a temporary
file beside the destination and renamed into place by `finish`, so that nothing half-written is
left under the name; `abandon` removes it.
"""

from __future__ import annotations

import contextlib
import os
import socket
import tempfile
import uuid
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np

from hoh_cosim.errors import ConfigError, RunError
from hoh_cosim.view import require_rerun
from hoh_cosim.view.scene import Scene, link_poses, quaternions, rotation_z_to
from hoh_cosim.view.track import Track

__all__ = [
    "FILE_BLOCK_ROWS",
    "FORCE_SCALE_M_PER_N",
    "STATUS_HOLD_S",
    "TWIST_SCALE_S",
    "ViewStream",
    "check_record_path",
    "free_loopback_port",
    "view_blueprint",
]

FORCE_SCALE_M_PER_N = 0.01
"""A force's arrow: 1 cm per newton."""
TWIST_SCALE_S = 1.0
"""A velocity's arrow: 1 m per m/s (1 cm per 10 mm/s)."""
STATUS_HOLD_S = 0.1
"""[s] A status bit's clearing is told in the view's log once it has held this long."""
FILE_BLOCK_ROWS = 500
"""Rows gathered before they go to a recording's file as one chunk per entity."""
_SPEED_LIMIT_MM_S = 100.0  # the supervisor's default (DESIGN.md §7), drawn on the speed's plot

_ARM = (120, 150, 190)
_JOINT = (70, 90, 125)
_HAND = (255, 140, 0)
_CONTACT = (40, 190, 90)
_COMMAND = (0, 190, 230)
_REPLAYED = (220, 60, 200)
_SKIN = (240, 190, 160, 120)
_FIXTURE = (250, 220, 0, 110)
_XYZ = ((230, 70, 70), (70, 180, 70), (70, 110, 230))
_XYZ_LIGHT = ((240, 160, 160), (160, 215, 160), (160, 180, 240))


def check_record_path(path: str | Path, option: str = "--record-view") -> Path:
    """`path` if a recording can be written there: a name ending in .rrd, in a folder that
    exists and takes files. Refused with one line before anything runs."""
    path = Path(path)
    if path.suffix != ".rrd":
        raise ConfigError(f"{option} {path}: expected a file name ending in .rrd")
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a folder; expected a file name ending in .rrd")
    folder = path.parent
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist"
        raise ConfigError(f"{option} {path}: the folder {folder} {what}")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".part", dir=folder)
    except OSError as exc:
        raise ConfigError(f"{option} {path}: cannot write in {folder}: {exc.strerror}") from None
    os.close(fd)
    os.unlink(probe)
    return path


def free_loopback_port() -> int:
    """A port free on 127.0.0.1 now (the gRPC servers': Rerun's would take port 0 but name 0)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def view_blueprint(timeline: str, replay: bool = False) -> Any:
    """The view's layout: the 3D view and the text log, the plots beside them."""
    import rerun.blueprint as rrb

    plots = [
        rrb.TimeSeriesView(origin="plots/hand_force", name="hand force [N]"),
        rrb.TimeSeriesView(origin="plots/contact_force", name="contact force [N]"),
        rrb.TimeSeriesView(origin="plots/tip_speed", name="tip speed [mm/s]"),
        rrb.TimeSeriesView(
            origin="plots/command" if replay else "plots/path_error",
            name="commanded velocity, logged and replayed [mm/s]" if replay else "path error [mm]",
        ),
    ]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(
                    origin="world",
                    name="base frame B",
                    eye_controls=rrb.EyeControls3D(
                        position=[0.75, 0.35, 0.62], look_target=[-0.12, -0.32, 0.28]
                    ),
                ),
                rrb.TextLogView(origin="log", name="mode, status and events"),
                row_shares=[4, 1],
            ),
            rrb.Vertical(*plots),
            column_shares=[3, 2],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="expanded", timeline=timeline),
    )


class ViewStream:
    """One view: live (`web_port`), recorded (`record`), or both. Built before anything runs:
    a missing Rerun, a port in use or a folder that takes no file are refused here."""

    def __init__(
        self,
        scene: Scene,
        *,
        title: str,
        timeline: str,
        web_port: int | None = None,
        record: str | Path | None = None,
        replay: bool = False,
    ) -> None:
        require_rerun("--view" if web_port is not None else "--record-view")
        import rerun as rr

        self.rr = rr
        self.scene = scene
        self.timeline = timeline
        self.replay = replay
        self.url: str | None = None
        self.record = None if record is None else check_record_path(record)
        self._part: Path | None = None
        self._targets: list[_Target] = []
        self._file: _Target | None = None
        blueprint = view_blueprint(timeline, replay)
        recording_id = uuid.uuid4()
        if web_port is not None:
            try:
                rr.serve_web_viewer(web_port=web_port, open_browser=False)
            except RuntimeError as exc:
                if "in use" in str(exc):
                    raise ConfigError(
                        f"--view-port {web_port}: the port is in use (another viewer or server "
                        "listens there); choose another with --view-port"
                    ) from None
                raise RunError(f"--view: Rerun's web viewer did not start: {exc}") from None
            sink = rr.GrpcServerSink(bind_ip="127.0.0.1", port=free_loopback_port())
            live = rr.RecordingStream("hoh-cosim", recording_id=recording_id)
            live.send_recording_name(title)
            live.set_sinks(sink, default_blueprint=blueprint)
            self._targets.append(_Target(live, 1))
            self.url = f"http://127.0.0.1:{web_port}/?url={quote(sink.uri, safe='')}"
        if self.record is not None:
            # a name of its own beside the destination, made with the umask's permissions
            self._part = self.record.with_name(f".{self.record.name}.{uuid.uuid4().hex[:8]}.part")
            self._part.open("xb").close()
            stream = rr.RecordingStream("hoh-cosim", recording_id=recording_id)
            stream.set_sinks(rr.FileSink(str(self._part)), default_blueprint=blueprint)
            stream.send_recording_name(title)
            self._file = _Target(stream, FILE_BLOCK_ROWS)
            self._targets.append(self._file)
        self._static()

    # --- sending -------------------------------------------------------------------------------

    def _log(self, path: str, *archetypes: Any, static: bool = False) -> None:
        for target in self._targets:
            target.stream.log(path, *archetypes, static=static)

    def _static(self) -> None:
        rr, scene = self.rr, self.scene
        self._log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        lo, hi = scene.workspace_min_B, scene.workspace_max_B
        self._log(
            "world/workspace",
            rr.Boxes3D(mins=[lo], sizes=[hi - lo], colors=[(150, 150, 150)], radii=0.002),
            static=True,
        )
        if scene.ur5:
            self._log(
                "world/arm/base",
                rr.Cylinders3D(
                    lengths=[0.09],
                    radii=[0.075],
                    centers=[[0, 0, 0.045]],
                    colors=[_JOINT],
                    fill_mode="solid",
                ),
                static=True,
            )
            from plant_models.ur5 import DH

            for i, (d, a, _) in enumerate(DH, start=1):
                housing = (0.13, 0.06) if i <= 3 else (0.10, 0.045)
                self._log(
                    f"world/arm/link{i}",
                    rr.Cylinders3D(
                        lengths=[housing[0]],
                        radii=[housing[1]],
                        centers=[[0, 0, 0]],
                        colors=[_JOINT],
                        fill_mode="solid",
                    ),
                    static=True,
                )
                lengths, translations, rotations = [], [], []
                if d > 0.0:
                    lengths.append(d)
                    translations.append([0.0, 0.0, 0.0])
                    rotations.append([0.0, 0.0, 0.0, 1.0])
                if a != 0.0:
                    lengths.append(abs(a))
                    translations.append([0.0, 0.0, d])
                    rotations.append(rotation_z_to(np.array([np.sign(a), 0.0, 0.0])))
                self._log(
                    f"world/arm/link{i}/segments",
                    rr.Capsules3D(
                        lengths=lengths,
                        radii=[0.04 if i <= 3 else 0.035] * len(lengths),
                        translations=translations,
                        quaternions=rotations,
                        colors=[_ARM] * len(lengths),
                        fill_mode="solid",
                    ),
                    static=True,
                )
        tool = scene.tool
        e, s, p, h = (float(v[2]) for v in (tool.p_TE_T, tool.p_TS_T, tool.p_TP_T, tool.p_TH_T))
        self._log(
            "world/probe/body",
            rr.Cylinders3D(
                lengths=[s - e, p - s],
                radii=[0.04, 0.032],
                centers=[[0, 0, 0.5 * (e + s)], [0, 0, 0.5 * (s + p)]],
                colors=[(60, 60, 60), (205, 205, 205)],
                fill_mode="solid",
            ),
            static=True,
        )
        self._log(
            "world/probe/transducer",
            rr.Boxes3D(
                half_sizes=[[0.012, 0.03, -0.5 * p]],
                centers=[[0, 0, 0.5 * p]],
                colors=[(235, 235, 235)],
                fill_mode="solid",
            ),
            static=True,
        )
        self._log(
            "world/probe/handle",
            rr.Capsules3D(
                lengths=[0.07],
                radii=[0.012],
                translations=[[-0.035, 0.0, h]],
                quaternions=[rotation_z_to(np.array([1.0, 0.0, 0.0]))],
                colors=[_HAND],
                fill_mode="solid",
            ),
            static=True,
        )
        self._log(
            "world/probe/tip",
            rr.Points3D([[0, 0, 0]], radii=0.007, colors=[(220, 40, 40)]),
            static=True,
        )
        for path, name, color in (
            ("plots/contact_force/magnitude", "|F contact|", _CONTACT),
            ("plots/contact_force/soft_cap", f"soft cap {scene.soft_cap_N:g} N", (230, 160, 0)),
            ("plots/contact_force/stop", f"stop {scene.stop_N:g} N", (220, 40, 40)),
            ("plots/tip_speed/magnitude", "|v tip|", _COMMAND),
            ("plots/tip_speed/limit", f"limit {_SPEED_LIMIT_MM_S:g} mm/s", (220, 40, 40)),
            ("plots/path_error/magnitude", "|tip - reference|", (150, 80, 220)),
        ):
            self._log(path, rr.SeriesLines(colors=[color], names=[name]), static=True)
        for path, label, colors in (
            ("plots/hand_force/hand", "", _XYZ),
            ("plots/hand_force/estimate", " estimated", _XYZ_LIGHT),
            ("plots/command/logged", "", _XYZ),
            ("plots/command/replayed", " replayed", _XYZ_LIGHT),
        ):
            self._log(
                path,
                rr.SeriesLines(colors=list(colors), names=[f"{c}{label}" for c in "xyz"]),
                static=True,
            )
        # what does not change from instant to instant is said once
        for path, color, label in (
            ("world/forces/hand", _HAND, "hand"),
            ("world/forces/contact", _CONTACT, "contact"),
            ("world/command/twist", _COMMAND, "command"),
            ("world/command/replayed", _REPLAYED, "replayed"),
        ):
            self._log(
                path,
                rr.Arrows3D.from_fields(colors=[color], radii=[0.004], labels=[label]),
                static=True,
            )
        self._log(
            "world/path/reference",
            rr.Points3D.from_fields(radii=[0.005], colors=[(150, 80, 220)]),
            static=True,
        )
        self._log(
            "world/fixture",
            rr.Boxes3D.from_fields(
                half_sizes=[[0.06, 0.06, 0.0005]], colors=[_FIXTURE], fill_mode="solid"
            ),
            static=True,
        )
        surface = scene.surface
        if surface is not None and surface.shape == "ellipsoid":
            self._log(
                "world/surface/shape",
                rr.Ellipsoids3D.from_fields(
                    centers=[surface.point_B], colors=[_SKIN], fill_mode="solid"
                ),
                static=True,
            )
        if scene.note:
            self._log("log/controller", rr.TextLog(scene.note, level="INFO"), static=True)

    def text(self, t: float, text: str, level: str = "INFO") -> None:
        """One line in the view's text log at time `t`."""
        for target in self._targets:
            self._columns(
                target,
                "log/controller",
                np.array([t]),
                self.rr.TextLog.columns(text=[text], level=[level]),
            )

    def log(self, track: Track) -> None:
        """Hand over a block of the track: sent at once to the live view, gathered into blocks of
        `FILE_BLOCK_ROWS` for the recording (few chunks: a small file)."""
        if len(track) == 0:
            return
        for target in self._targets:
            target.pending.append(track)
            target.rows += len(track)
            if target.rows >= target.batch_rows:
                self._flush(target)

    def _flush(self, target: _Target) -> None:
        if not target.pending:
            return
        track = Track.concatenate(target.pending) if len(target.pending) > 1 else target.pending[0]
        target.pending, target.rows = [], 0
        self._send(target, track)

    def _columns(self, target: _Target, path: str, times: np.ndarray, columns: Any) -> None:
        index = [self.rr.TimeColumn(self.timeline, duration=times)]
        target.stream.send_columns(path, indexes=index, columns=columns)

    def _send(self, target: _Target, track: Track) -> None:
        rr, scene, t = self.rr, self.scene, track.t
        if track.q is not None and scene.ur5:
            frames = link_poses(track.q)  # (n, 6, 4, 4): L_1..L_6
            for i in range(6):
                L = frames[:, i]
                self._columns(
                    target,
                    f"world/arm/link{i + 1}",
                    t,
                    rr.Transform3D.columns(
                        translation=L[:, :3, 3], quaternion=quaternions(L[:, :3, :3])
                    ),
                )
        self._columns(
            target,
            "world/probe",
            t,
            rr.Transform3D.columns(translation=track.p_BT_B, quaternion=quaternions(track.R_BT)),
        )
        p_BH = track.p_BT_B + track.R_BT @ scene.tool.p_TH_T
        for path, origins, vectors in (
            ("world/forces/hand", p_BH, track.F_hand_B),
            ("world/forces/contact", track.p_BT_B, track.F_contact_B),
            ("world/command/twist", track.p_BT_B, track.twist_cmd_B),
            ("world/command/replayed", track.p_BT_B, track.twist_replayed_B),
        ):
            if vectors is None:
                continue
            scale = FORCE_SCALE_M_PER_N if path.startswith("world/forces") else TWIST_SCALE_S
            self._columns(
                target,
                path,
                t,
                rr.Arrows3D.columns(origins=origins, vectors=scale * np.nan_to_num(vectors[:, :3])),
            )
        if track.p_ref_B is not None:
            self._columns(
                target, "world/path/reference", t, rr.Points3D.columns(positions=track.p_ref_B)
            )
        self._surface(target, track)
        self._fixture(target, track)
        self._plots(target, track)
        self._transitions(target, track)

    def _surface(self, target: _Target, track: Track) -> None:
        surface = self.scene.surface
        if surface is None:
            return
        rr = self.rr
        offset = track.surface_offset_m
        if surface.shape == "ellipsoid":  # grows along its normals with the breath
            h = np.zeros(len(track)) if offset is None else offset
            self._columns(
                target,
                "world/surface/shape",
                track.t,
                rr.Ellipsoids3D.columns(half_sizes=surface.axes[None, :] + h[:, None]),
            )
            return
        n_B = surface.normal_B / np.linalg.norm(surface.normal_B)
        if target.surface_at is None:  # a patch of the plane under the tip's first position
            tip = track.p_BT_B[0]
            target.surface_at = tip - float((tip - surface.point_B) @ n_B) * n_B
            target.stream.log(
                "world/surface/shape",
                rr.Boxes3D(
                    half_sizes=[[0.25, 0.25, 0.002]],
                    centers=[target.surface_at],
                    quaternions=[rotation_z_to(n_B)],
                    colors=[_SKIN],
                    fill_mode="solid",
                ),
                static=True,
            )
        if offset is not None:
            self._columns(
                target,
                "world/surface",
                track.t,
                rr.Transform3D.columns(translation=offset[:, None] * n_B[None, :]),
            )

    def _fixture(self, target: _Target, track: Track) -> None:
        """The fixture's plane at the tip on the rows where it is engaged, none on the others."""
        if track.status is None:
            return
        from hoh_cosim.control.supervisor import Status

        engaged = (track.status.astype(np.int64) & int(Status.FIXTURE)) != 0
        if not engaged.any() and not target.fixture_shown:
            return
        target.fixture_shown = True
        ups = np.tile(self.scene.fixture_up_B, (len(track), 1))
        if self.scene.fixture_follows_contact and track.F_contact_B is not None:
            size = np.linalg.norm(track.F_contact_B, axis=1, keepdims=True)
            ups = np.where(size > 0.0, track.F_contact_B / np.where(size > 0, size, 1.0), ups)
        rows = np.flatnonzero(engaged)
        columns = self.rr.Boxes3D.columns(
            centers=track.p_BT_B[rows],
            quaternions=np.array([rotation_z_to(u) for u in ups[rows]]).reshape(-1, 4),
        )
        self._columns(
            target, "world/fixture", track.t, columns.partition(engaged.astype(int).tolist())
        )

    def _plots(self, target: _Target, track: Track) -> None:
        rr, t = self.rr, track.t
        ends = t[[0, -1]]  # a constant line needs its ends only
        for path, values in (
            ("plots/hand_force/hand", track.F_hand_B),
            ("plots/hand_force/estimate", track.F_hand_est_B),
            ("plots/command/logged", _mm(track.twist_cmd_B) if self.replay else None),
            ("plots/command/replayed", _mm(track.twist_replayed_B)),
        ):
            if values is not None:
                self._columns(target, path, t, rr.Scalars.columns(scalars=values))
        if track.F_contact_B is not None:
            self._columns(
                target,
                "plots/contact_force/magnitude",
                t,
                rr.Scalars.columns(scalars=np.linalg.norm(track.F_contact_B, axis=1)),
            )
            for path, level in (
                ("plots/contact_force/soft_cap", self.scene.soft_cap_N),
                ("plots/contact_force/stop", self.scene.stop_N),
            ):
                self._columns(target, path, ends, rr.Scalars.columns(scalars=[level, level]))
        if track.v_B is not None:
            self._columns(
                target,
                "plots/tip_speed/magnitude",
                t,
                rr.Scalars.columns(scalars=1e3 * np.linalg.norm(track.v_B, axis=1)),
            )
            self._columns(
                target,
                "plots/tip_speed/limit",
                ends,
                rr.Scalars.columns(scalars=[_SPEED_LIMIT_MM_S] * 2),
            )
        if track.p_ref_B is not None:
            error = 1e3 * np.linalg.norm(track.p_BT_B - track.p_ref_B, axis=1)
            self._columns(
                target, "plots/path_error/magnitude", t, rr.Scalars.columns(scalars=error)
            )

    def _transitions(self, target: _Target, track: Track) -> None:
        """The mode's and the status bits' changes within the block (and from the last one), one
        line per instant. A bit set is told at once, a bit cleared once it has stayed clear for
        `STATUS_HOLD_S` (a stop flag's at once): a clamp that comes and goes every few cycles is
        two lines, not dozens."""
        from hoh_cosim.control.guidance.modes import Mode
        from hoh_cosim.control.supervisor import STOP_FLAGS, Status

        status = np.zeros(len(track)) if track.status is None else track.status
        mode = np.full(len(track), np.nan) if track.mode is None else track.mode
        stops = int(STOP_FLAGS)
        times, texts, levels = [], [], []
        for t, s, m in zip(
            track.t.tolist(), status.astype(np.int64).tolist(), mode.tolist(), strict=True
        ):
            parts, stop = [], False
            if m != target.mode and np.isfinite(m):
                target.mode = m
                try:
                    parts.append(f"mode: {Mode(int(m)).label}")
                except ValueError:  # a mode this version does not know
                    parts.append(f"mode {m:g}")
            on = s & ~target.status  # set: told at once
            cleared = target.status & ~s
            for bit in list(target.since):  # cleared, then set again before it held
                if not cleared & bit:
                    del target.since[bit]
            off = 0
            for bit in (1 << i for i in range(cleared.bit_length())):
                if cleared & bit:
                    since = target.since.setdefault(bit, t)
                    if bit & stops or t - since >= STATUS_HOLD_S - 1e-9:
                        del target.since[bit]
                        off |= bit
            target.status = (target.status | on) & ~off
            if on:
                parts.append(f"status + {Status(on).describe()}")
                stop = bool(on & stops)
            if off:
                parts.append(f"status - {Status(off).describe()}")
            if parts:
                times.append(t)
                texts.append("; ".join(parts))
                levels.append("WARN" if stop else "INFO")
        if texts:
            self._columns(
                target,
                "log/controller",
                np.array(times),
                self.rr.TextLog.columns(text=texts, level=levels),
            )

    # --- the end -------------------------------------------------------------------------------

    def finish(self) -> Path | None:
        """Complete the recording and move it into place (its path); the live view stays."""
        target, self._file = self._file, None
        if target is None:
            return None
        self._flush(target)
        self._targets.remove(target)
        target.stream.flush()
        target.stream.disconnect()
        assert self._part is not None
        assert self.record is not None
        if not self._part.is_file() or self._part.stat().st_size == 0:
            raise RunError(f"--record-view {self.record}: Rerun wrote nothing")
        os.replace(self._part, self.record)
        self._part = None
        return self.record

    def abandon(self) -> None:
        """Drop the recording (nothing is left under its name) and end the live view."""
        target, self._file = self._file, None
        if target is not None:
            self._targets.remove(target)
            with contextlib.suppress(Exception):
                target.stream.disconnect()
        if self._part is not None:
            self._part.unlink(missing_ok=True)
            self._part = None
        self.close()

    def close(self) -> None:
        """End the live view (the web viewer's page stays served until the process ends); a
        recording not finished is abandoned."""
        if self._file is not None:
            self.abandon()
            return
        for target in self._targets:
            with contextlib.suppress(Exception):
                self._flush(target)
                target.stream.flush()
                target.stream.disconnect()
        self._targets = []


def _mm(twist: np.ndarray | None) -> np.ndarray | None:
    """A twist's linear part in mm/s."""
    return None if twist is None else 1e3 * twist[:, :3]


class _Target:
    """One recording stream the view goes to, and what it was last sent."""

    def __init__(self, stream: Any, batch_rows: int) -> None:
        self.stream = stream
        self.batch_rows = batch_rows  # rows gathered before they are sent
        self.pending: list[Track] = []
        self.rows = 0
        self.status = 0  # the status bits told
        self.mode = np.nan  # the mode told
        self.since: dict[int, float] = {}  # a bit that differs from the one told: since when
        self.surface_at: np.ndarray | None = None  # the plane's patch, once placed
        self.fixture_shown = False
