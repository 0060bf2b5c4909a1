"""The conveyor line as a headless pybullet world: belt, end roller, floor and fillet chains.

World frame and dimensions come from :class:`woody_sim.line_geometry.LineGeometry`
(x downstream, y left, z up, belt top z = 0 ending at the roller edge x = 0).
Each fillet is a pybullet multibody chain built from a
:class:`woody_sim.fillet_model.FilletModel`: one box link per slice, revolute
hinges about y with +-130 deg limits, no self-collision.

Choices that are not pybullet defaults (measurements in docs/physics.md):

* **Hinge spring-damper tau = -k theta - c theta_dot, implicit in time.**
  pybullet has no joint springs, and an explicit torque spring-damper is
  unstable on the light tip segments unless the step is ~10 us (the tip's
  inertia is ~1e-7 kg m^2, so c / I alone is 1e5 1/s). The hinge torques are
  therefore computed every step as a backward-Euler spring-damper, i.e. the
  torque at the *end* of the step, using the chain's joint-space inertia from
  pybullet's mass matrix (floating base eliminated) and the other hinge loads
  (contacts, drive, limits) observed over the previous step - a "stable PD"
  (Tan, Liu & Turk 2011) with a disturbance estimate. The torques go to
  pybullet as ordinary joint torques; pybullet integrates everything else.
* **Kinematic belt drive (paper: F = m (V_line - V) / dt).** A segment whose
  contact with the conveyor has an upward normal (the flat belt) is pushed to
  line speed along +x every step; on the roller (tilted normal) or without
  contact the drive lets go and gravity takes over. Belt and roller are static
  bodies without friction (friction against a static belt would brake the
  fillet the real belt carries), so the drive alone sets the speed.
* **Inertia floor on the hinge axis.** No segment's inertia about y is below
  ``PhysicsConfig.inertia_floor`` (30 %) of the mean segment's: the thin end
  slices otherwise whip under a roller contact (:func:`segment_inertias`).
* **Flat-belt fast path.** Bullet's articulated contact cost grows with
  (contacts x links), and a fillet lying flat on the belt at line speed is a
  rigid translation anyway. A fillet therefore rides the belt as an exact
  kinematic translation until its leading end is ``activation_margin`` from
  the roller edge, and only then becomes a pybullet chain (flat, at line
  speed). ``activation_margin = None`` simulates the whole belt run.
* **Fillets do not collide with one another**, only with the conveyor and
  floor: on a crowded line they may touch or overlap, and two fillets in the
  two worlds of :mod:`woody_sim.split_world` could not push each other anyway.
* **One belt speed for all.** :meth:`LineWorld.change_speed` sets, from a
  given step, the speed the belt carries every fillet at: riding fillets
  continue analytically from where the old speed brought them, chains are
  driven towards the new speed.
"""

from __future__ import annotations

import ctypes
import gc
import itertools
import math
from collections.abc import Container
from dataclasses import dataclass, field

import numba
import numpy as np
import pybullet as p

from woody_common.calibration import Calibration, resolved_calibration
from woody_common.line import MAX_SPEED_MPS, PAPER_PHYSICS_RATE_HZ, PAPER_SEGMENTS
from woody_sim import fillet_model, meshes
from woody_sim.belt_drive import belt_drive
from woody_sim.disk_cache import cached, digest
from woody_sim.fillet_model import DEFAULT_SEGMENTS, NOMINAL_MASS, FilletModel, build_fillet_model
from woody_sim.hinge_law import chain_mass_matrix, hinge_state, implicit_hinge_torque
from woody_sim.line_geometry import LineGeometry
from woody_sim.meshes import DERIVED_MARK, FilletMesh

MAX_MASS = 1000.0
DEFAULT_DAMPING = 0.05
"""The seed's hinge damper in its side-view and combined scenes (the calibration may choose another)."""
JOINT_LIMIT = math.radians(130.0)
CONTACT_DISTANCE = 0.001
"""A conveyor contact counts as touching (for the drive) below this separation (m)."""
PAST_ROLLER_X = 1.5
"""A fillet whose centre of mass is this far (m) downstream of the roller edge has left the line."""
DYNAMIC_TIMEOUT = 10.0
"""A chain still on the line this long (s) after leaving the belt fast path is removed (stuck), so runs stay bounded."""
FILLET_COLLISION_GROUP = 4
"""Collision filter group of fillet chains; their mask leaves it out, so chains touch only the conveyor and floor
(pybullet's default groups 1 and 2)."""
FILLET_COLLISION_MASK = 3
BLOWUP_SPEED = 12.0
"""m/s no segment reaches on this line (free fall past the roller stays under ~4 m/s): faster is a numerical blow-up."""


SLICE_SHAPES = ("box", "capsule")


@dataclass(frozen=True)
class PhysicsConfig:
    """Integration and contact settings; the defaults are the validated production values."""

    dt: float = 1.0 / 360.0
    """Seconds per :meth:`LineWorld.step` = one pybullet step (motors and drive update every step; the paper's
    chain steps at 480 Hz, which its 40 slices need)."""
    n_segments: int = DEFAULT_SEGMENTS
    damping: float = DEFAULT_DAMPING
    """Hinge damping c (N m s / rad)."""
    activation_margin: float | None = 0.02
    """Distance (m) from the roller edge at which a fillet's leading end stops riding kinematically."""
    belt_friction: float = 0.0
    """The belt and roller are static bodies, so any friction would brake the fillet the real
    belt carries; the drive supplies the traction instead."""
    solver_iterations: int = 20
    friction_static: float = 0.8
    """Coulomb cap of the belt drive while the segment holds the belt speed (seed: static 0.8)."""
    friction_dynamic: float = 0.6
    """Coulomb cap once the needed force exceeds the static cap (seed: dynamic 0.6)."""
    normal_force_tau: float = 0.01
    """Time constant (s) of the low-pass filter on the contact normal force that caps the drive."""
    inertia_floor: float = 0.3
    """Least inertia of a segment about its hinge axis, as a fraction of the segments' mean (an armature on the
    thin tip slices, without which pybullet's contact solver whips them; see :func:`segment_inertias`)."""
    island_sleeping: bool = False
    """Let Bullet put a chain to sleep once it comes to rest (its simulation island drops out of the solver). On
    the line no chain rests: each rides the belt kinematically until the roller and is removed once it fell."""
    slice_shape: str = "box"
    """Collision shape of a slice: 'box' (its bounding box: up to four contact points with the belt or the
    roller) or 'capsule' (a capsule across the flow, as wide as the box, its radius the smaller of the box's
    half length and half thickness, its bottom on the box's bottom: one or two contact points)."""

    @property
    def resolution(self) -> str:
        """The chain's resolution and step, as results made with them are labelled ('24 slices at 360 Hz, 20
        iterations')."""
        return f"{self.n_segments} slices at {1.0 / self.dt:g} Hz, {self.solver_iterations} iterations"

    @property
    def hinge_scale(self) -> float:
        """What one hinge of this chain carries of the paper's k and c (N / PAPER_SEGMENTS).

        The paper's k and c belong to each hinge of its 40-slice chain. A chain of N slices is the same fillet at
        another resolution when each hinge bends like the PAPER_SEGMENTS / N paper hinges it stands for: springs
        and dampers in series, so k and c scale by N / 40 and the fillet's bending stiffness (k times the slice
        length) stays. Without it fewer, longer slices would be a stiffer fillet at the same k
        (docs/physics.md, "What each setting costs and what it changes")."""
        return self.n_segments / PAPER_SEGMENTS

    def __post_init__(self) -> None:
        if not 1e-7 <= self.dt <= 0.02:
            raise ValueError(f"dt must be within 1e-7..0.02 s, got {self.dt}")
        if int(self.n_segments) != self.n_segments or self.n_segments < 2:
            raise ValueError(f"number of segments N must be an integer >= 2, got {self.n_segments}")
        if not self.damping >= 0.0:
            raise ValueError(f"damping must be >= 0, got {self.damping}")
        if not 0.0 <= self.inertia_floor <= 1.0:
            raise ValueError(f"inertia_floor must be within 0..1, got {self.inertia_floor}")
        if self.slice_shape not in SLICE_SHAPES:
            raise ValueError(f"slice_shape must be one of {', '.join(SLICE_SHAPES)}, got {self.slice_shape!r}")
        if self.activation_margin is not None and not self.activation_margin >= 0.0:
            raise ValueError(f"activation_margin must be >= 0 or None, got {self.activation_margin}")


PAPER_PHYSICS = {"n_segments": PAPER_SEGMENTS, "dt": 1.0 / PAPER_PHYSICS_RATE_HZ}
"""PhysicsConfig overrides for the paper's own chain: 40 slices stepped at 480 Hz (docs/physics.md)."""


@dataclass(frozen=True)
class FilletInfo:
    """What was spawned (the ground truth the grader is scored against)."""

    fillet_id: int
    lane: int
    mesh_name: str
    k: float
    mass: float
    speed_mps: float
    spawn_time: float


@dataclass(eq=False)
class _Fillet:
    """Book-keeping for one fillet; ``body`` is -1 while it rides the belt kinematically."""

    info: FilletInfo
    mesh: FilletMesh
    model: FilletModel
    origin: np.ndarray
    """Fillet-frame origin in the world at ``ride_start`` (kinematic phase: moves at ``speed`` from there)."""
    speed: float
    """Belt speed (m/s) carrying the fillet now: its spawn speed until the belt speed changes."""
    ride_start: float
    """Sim time at which the fillet was at ``origin``: its spawn, or the last belt speed change since."""
    body: int = -1
    physics: _Physics | None = None
    """The pybullet world the chain lives in (None while it rides the belt)."""
    activation_time: float = math.inf
    state: np.ndarray = field(default_factory=lambda: np.zeros((0, 13)))
    """(N, 13) per segment after the last step: position, quaternion (x, y, z, w), linear and angular velocity."""
    drive: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(N, 3) belt drive force on each segment being applied (N, world frame)."""
    normal_force: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(N,) low-pass filtered conveyor contact normal force on each segment (N), which caps the drive."""
    torque: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(N - 1,) hinge torques applied in the last step."""
    rate: np.ndarray = field(default_factory=lambda: np.zeros(0))
    """(N - 1,) hinge rates at the start of the last step."""
    inertias: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(N, 3) principal inertias the chain was built with (:func:`segment_inertias`)."""
    joint_offsets: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    """(N - 1, 3) hinge i to the centre of segment i + 1, in that segment's frame."""


RELEASES_PER_COLLECT = 50
"""A world runs Python's full garbage collection after releasing this many placed meshes (:meth:`LineWorld.release`).
A trimesh is in a reference cycle with its visuals, so only the cyclic collector frees a placed mesh; a fillet's
mesh lives for seconds, long enough to reach the oldest generation, whose collections come rarer as a line runs.
Without this a messy line's process grew by 60-100 MB per 1,000 fillets (`woody soak --shift`); one collection
costs tens of milliseconds."""
CHAINS_PER_PHYSICS = 200
"""Chains one pybullet world builds before later ones go to a fresh world (:class:`_Physics`)."""


def _conveyor_contacts(physics: _Physics) -> np.ndarray:
    """(K, 5) [body, segment, normal x, normal z, normal force (N)] of every chain's contact with the conveyor."""
    # contact[7] points from the fillet to the conveyor; contact[9] is the normal force (N)
    return np.array([(c[2], c[4] + 1, c[7][0], c[7][2], c[9])
                     for c in p.getContactPoints(bodyA=physics.conveyor, physicsClientId=physics.client)
                     if c[8] < CONTACT_DISTANCE]).reshape(-1, 5)


class _Physics:
    """One pybullet world (a DIRECT client): conveyor, floor and the chains built in it.

    pybullet never frees a collision shape a body has used, and keeps some memory of every removed body, so a
    world that builds chains for hours grows without end (each fillet of a messy line has its own shapes).
    A :class:`LineWorld` therefore builds at most ``CHAINS_PER_PHYSICS`` chains in one world, then builds the
    next ones in a fresh world and closes the old one when its last chain is gone, which frees what pybullet
    held of them. Chains never touch one another, so a chain moves the same in whichever world it is.
    """

    def __init__(self, geometry: LineGeometry, config: PhysicsConfig) -> None:
        self.client = p.connect(p.DIRECT)
        self.built = 0
        """Chains built in this world so far."""
        self.live = 0
        """Chains in this world now."""
        self.shapes: dict[FilletMesh, list[int]] = {}
        p.setGravity(0.0, 0.0, -9.81, physicsClientId=self.client)
        p.setPhysicsEngineParameter(
            fixedTimeStep=config.dt,
            numSubSteps=0,
            numSolverIterations=config.solver_iterations,
            deterministicOverlappingPairs=1,
            # Belt and roller are frictionless (the drive supplies the traction), so the implicit friction cone
            # only adds solver work: without it the trajectories are bit-identical and stepSimulation ~5 % cheaper.
            enableConeFriction=0,
            physicsClientId=self.client,
        )
        self.conveyor = self._build_conveyor(geometry, config)

    def _build_conveyor(self, g: LineGeometry, config: PhysicsConfig) -> int:
        """Flat belt box (top z = 0, x from -belt_length to 0), end roller along y, catch floor."""
        c = self.client
        radius = g.roller_radius
        shape = p.createCollisionShapeArray(
            shapeTypes=[p.GEOM_BOX, p.GEOM_CYLINDER],
            halfExtents=[[g.belt_length / 2.0, g.belt_width / 2.0, radius / 2.0], [0.0, 0.0, 0.0]],
            radii=[0.0, radius],
            lengths=[0.0, g.belt_width],
            collisionFramePositions=[[-g.belt_length / 2.0, 0.0, -radius / 2.0], [0.0, 0.0, -radius]],
            collisionFrameOrientations=[[0.0, 0.0, 0.0, 1.0], p.getQuaternionFromEuler([math.pi / 2.0, 0.0, 0.0])],
            physicsClientId=c,
        )
        conveyor = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape, physicsClientId=c)
        p.changeDynamics(conveyor, -1, lateralFriction=config.belt_friction, restitution=0.0, physicsClientId=c)
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=c)
        floor = p.createMultiBody(
            baseMass=0.0, baseCollisionShapeIndex=plane, basePosition=[0.0, 0.0, g.floor_z], physicsClientId=c
        )
        p.changeDynamics(floor, -1, lateralFriction=0.8, restitution=0.0, physicsClientId=c)
        return conveyor

    @property
    def full(self) -> bool:
        return self.built >= CHAINS_PER_PHYSICS

    def close(self) -> None:
        if self.client >= 0:
            p.disconnect(physicsClientId=self.client)
            self.client = -1


def return_freed_memory() -> None:
    """Give the heap a closed world freed back to the system (glibc's malloc_trim; nothing elsewhere).

    A world's many small allocations, freed at its close, stay in the process's heap among live ones, and the
    next world only partly reuses them, so a line that runs for hours grows without it (measured by `woody soak
    --shift`, docs/physics.md)."""
    if _LIBC is not None:
        _LIBC.malloc_trim(0)


def _glibc():
    try:
        libc = ctypes.CDLL("libc.so.6")
        return libc if hasattr(libc, "malloc_trim") else None
    except OSError:
        return None


_LIBC = _glibc()


def seed_dynamic_friction(friction_static: float) -> float:
    """The slipping cap that goes with a static cap, at the seed's ratio 0.6 / 0.8."""
    return round(0.75 * float(friction_static), 6)


def calibrated_config(calibration: Calibration | None = None, **overrides) -> PhysicsConfig:
    """PhysicsConfig with the calibrated damper and drive friction, plus overrides (``calibration`` None: the
    resolved one, woody_common.calibration.resolve_calibration)."""
    cal = calibration or resolved_calibration()
    values = {"damping": cal.hinge_damping, "friction_static": cal.friction_static,
              "friction_dynamic": cal.friction_dynamic}
    return PhysicsConfig(**{**values, **overrides})


def _check_positive_finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f"{name} must be a positive finite number, got {value}")
    return value


def segment_inertias(model: FilletModel, floor: float) -> np.ndarray:
    """(N, 3) principal inertias (kg m^2) of the segment boxes; the one about y at least ``floor`` x their mean.

    A tapering end slice is a thin, light box: its inertia about the hinge axis
    is ~1e-3 of a mid slice's. When such a slice carries the roller contact of
    a heavy chain, pybullet's iterative contact solver cannot balance it against
    its neighbours within a step and the tip whips (hinge rates hit Bullet's
    100 rad/s clamp, the chain is thrown: docs/physics.md, "Stability"). The
    floor is an armature on those hinges; mass, centre of mass and the other
    axes are unchanged.
    """
    m = model.masses
    size2 = (2.0 * model.box_half_extents) ** 2
    inertia = np.column_stack([size2[:, 1] + size2[:, 2], size2[:, 0] + size2[:, 2], size2[:, 0] + size2[:, 1]])
    inertia *= m[:, None] / 12.0
    inertia[:, 1] = np.maximum(inertia[:, 1], floor * inertia[:, 1].mean())
    return inertia


def chain_model(mesh: FilletMesh, n_segments: int) -> FilletModel:
    """The chain model of ``mesh`` with ``n_segments`` segments (masses for the nominal M), from the disk cache
    when an earlier run built it (:mod:`woody_sim.disk_cache`). A turned or scaled copy (a messy line's fillet)
    is used once and is built, not cached."""
    if DERIVED_MARK in mesh.source:
        return build_fillet_model(mesh, n_segments, NOMINAL_MASS)
    key = digest((fillet_model, meshes), mesh.name, n_segments, NOMINAL_MASS, mesh.mesh.vertices.tobytes(),
                 mesh.mesh.faces.tobytes())
    return cached("models", key, lambda: build_fillet_model(mesh, n_segments, NOMINAL_MASS), FilletModel)


class LineWorld:
    """A headless (p.DIRECT) pybullet conveyor with fillet chains; one instance per physics client."""

    def __init__(self, geometry: LineGeometry | None = None, config: PhysicsConfig | None = None) -> None:
        self.geometry = geometry or LineGeometry()
        self.config = config or PhysicsConfig()
        self.time = 0.0
        self._steps = 0
        self._physics = [_Physics(self.geometry, self.config)]
        """The pybullet worlds with chains in them, the one new chains are built in last."""
        self._fillets: dict[int, _Fillet] = {}
        self._removed: list[int] = []
        self.blown_up: list[int] = []
        """Ids of fillets removed because their chain blew up numerically (a known, rare edge instability)."""
        self._models: dict[FilletMesh, FilletModel] = {}
        self._released = 0
        self._next_id = 0
        self._speed_changes: list[tuple[float, float]] = []
        """(sim time, belt speed m/s) to apply at the first step at or after that time, soonest first."""
        self._speed_history: list[tuple[float, float]] = []
        """(sim time, belt speed m/s) of the changes applied, for fillets spawned in the past (a worker world)."""

    def close(self) -> None:
        """Disconnect the physics clients (the world is unusable afterwards)."""
        for physics in self._physics:
            physics.close()

    def __enter__(self) -> LineWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ fillets

    def model_for(self, mesh: FilletMesh, built: FilletModel | None = None) -> FilletModel:
        """The chain geometry for a mesh at this world's N (cached per mesh; masses for the default M); ``built``
        is that model built elsewhere (another world's, sent to a worker), kept instead of building it again."""
        if mesh not in self._models:
            self._models[mesh] = built or chain_model(mesh, self.config.n_segments)
        return self._models[mesh]

    def release(self, mesh: FilletMesh) -> None:
        """Forget the chain model built for a mesh no later spawn uses (a placed fillet's own mesh); pybullet
        keeps its collision shapes until the world they are in closes (:class:`_Physics`)."""
        self._models.pop(mesh, None)
        for physics in self._physics:
            physics.shapes.pop(mesh, None)
        self._released += 1
        if self._released % RELEASES_PER_COLLECT == 0:
            gc.collect()

    def spawn(
        self, mesh: FilletMesh, k: float, lane: int, mass: float, speed_mps: float, fillet_id: int | None = None,
        spawn_time: float | None = None, lateral_offset: float = 0.0,
    ) -> int:
        """Place a fillet flat on the belt at ``geometry.spawn_x`` in ``lane``, already moving at line speed.

        ``k`` is the hinge stiffness (N m / rad), ``mass`` the total chain mass M
        (kg), ``speed_mps`` the line speed, ``lateral_offset`` (m, along +y) its
        centre from the lane centre. Returns the fillet's id:
        ``fillet_id`` if given (it must not be live), else one never used before.
        ``spawn_time`` (at most now) places a fillet that entered earlier where the
        belt has carried it since: exact, because a fillet moves analytically until
        it nears the roller (a worker world hears of its spawns a few steps late).
        """
        k, lane, mass, speed = check_spawn(self.geometry, k, lane, mass, speed_mps)
        offset = check_lateral_offset(lateral_offset)
        fillet_id = check_fillet_id(self._next_id if fillet_id is None else fillet_id, self._fillets)
        spawn_time = self._check_spawn_time(spawn_time)
        self._next_id = max(self._next_id, fillet_id + 1)
        model = self.model_for(mesh).with_mass(mass)
        info = FilletInfo(fillet_id, lane, mesh.name, k, mass, speed, spawn_time)
        origin = np.array([self.geometry.spawn_x, self.geometry.lane_y(lane) + offset, 0.0])
        fillet = _Fillet(info=info, mesh=mesh, model=model, origin=origin, speed=speed, ride_start=spawn_time,
                         drive=np.zeros((model.n_segments, 3)), normal_force=np.zeros(model.n_segments))
        for at, new_speed in self._speed_history:  # changes applied since a past spawn_time (a worker world)
            if at >= spawn_time - 1e-9:
                self._ride_on(fillet, at, new_speed)
        self._fillets[fillet_id] = fillet
        self._kinematic_state(fillet)
        if self.config.activation_margin is None:
            self._activate(fillet)
        return fillet_id

    def _check_spawn_time(self, spawn_time: float | None) -> float:
        if spawn_time is None:
            return self.time
        if self.config.activation_margin is None:
            raise ValueError("a past spawn_time needs fillets that start on the belt (activation_margin set)")
        if not 0.0 <= spawn_time <= self.time:
            raise ValueError(f"spawn_time must be within 0..{self.time} s (now), got {spawn_time}")
        return float(spawn_time)

    def change_speed(self, speed_mps: float, at_time: float | None = None) -> None:
        """From the first step at or after sim time ``at_time`` (default: now) the belt carries every fillet on it
        at ``speed_mps``; fillets spawned later ride at the speed they are spawned with."""
        speed = _check_speed(speed_mps)
        at = self.time if at_time is None else float(at_time)
        if not at >= self.time - 1e-9:
            raise ValueError(f"a belt speed change must come at or after now ({self.time} s), got {at_time!r}")
        self._speed_changes.append((at, speed))
        self._speed_changes.sort(key=lambda change: change[0])

    def _apply_speed_changes(self) -> None:
        while self._speed_changes and self._speed_changes[0][0] <= self.time + 1e-9:
            _, speed = self._speed_changes.pop(0)
            for fillet in self._fillets.values():
                self._ride_on(fillet, self.time, speed)
            self._speed_history.append((self.time, speed))

    @staticmethod
    def _ride_on(fillet: _Fillet, at: float, speed: float) -> None:
        """From sim time ``at`` the belt carries the fillet at ``speed``: a riding fillet's analytic motion
        restarts there from where the old speed brought it; a chain's drive pulls towards the new speed."""
        if fillet.body < 0:
            fillet.origin[0] += fillet.speed * (at - fillet.ride_start)
            fillet.ride_start = at
            if fillet.state.shape[0]:
                fillet.state[:, 7] = speed
        fillet.speed = speed

    def _kinematic_state(self, fillet: _Fillet) -> None:
        """Flat pose translated at belt speed since ``ride_start`` (the exact flat-belt motion); only x changes."""
        shift = fillet.speed * (self.time - fillet.ride_start)
        x = fillet.origin[0] + shift + fillet.model.box_centers[:, 0]
        if fillet.state.shape[0] != fillet.model.n_segments:
            fillet.state = np.zeros((fillet.model.n_segments, 13))
            fillet.state[:, 1:3] = fillet.origin[1:] + fillet.model.box_centers[:, 1:]
            fillet.state[:, 6] = 1.0
            fillet.state[:, 7] = fillet.speed
        fillet.state[:, 0] = x

    def _leading_x(self, fillet: _Fillet) -> float:
        return float(fillet.state[-1, 0] + fillet.model.box_half_extents[-1, 0])

    def _collision_shapes(self, physics: _Physics, mesh: FilletMesh, model: FilletModel) -> list[int]:
        """Box shapes for a chain in ``physics`` (cached per mesh: pybullet cannot free a shape a body has used).

        Segment 0 is the base (box at its origin); segment i hangs from hinge
        i - 1, so its box is offset from its link frame by centre - hinge.
        """
        if mesh not in physics.shapes:
            centers, hinges = model.box_centers, model.joint_positions
            offsets = [np.zeros(3)] + [centers[i] - hinges[i - 1] for i in range(1, model.n_segments)]
            physics.shapes[mesh] = [self._slice_shape(physics.client, half, offset)
                                    for half, offset in zip(model.box_half_extents, offsets)]
        return physics.shapes[mesh]

    def _slice_shape(self, client: int, half: np.ndarray, offset: np.ndarray) -> int:
        """One slice's collision shape (``PhysicsConfig.slice_shape``) around a box of half extents ``half``
        centred ``offset`` from its link frame."""
        if self.config.slice_shape == "box":
            return p.createCollisionShape(p.GEOM_BOX, halfExtents=half.tolist(), collisionFramePosition=offset.tolist(),
                                          physicsClientId=client)
        radius = float(min(half[0], half[2]))
        bottom = offset + np.array([0.0, 0.0, radius - half[2]])
        across = p.getQuaternionFromEuler([math.pi / 2.0, 0.0, 0.0])  # the capsule's axis (z) along y
        return p.createCollisionShape(p.GEOM_CAPSULE, radius=radius, height=max(2.0 * (half[1] - radius), 1e-4),
                                      collisionFramePosition=bottom.tolist(), collisionFrameOrientation=across,
                                      physicsClientId=client)

    def _activate(self, fillet: _Fillet) -> None:
        """Turn a kinematic fillet into a pybullet chain at its current pose, flat and at line speed.

        A link's frame sits on its hinge; its inertial frame and box sit at the
        box centre, so pybullet's link (centre-of-mass) pose is the segment
        frame of :class:`FilletModel`.
        """
        if self._physics[-1].full:
            self._physics.append(_Physics(self.geometry, self.config))
        physics = self._physics[-1]
        c = physics.client
        model = fillet.model
        n = model.n_segments
        centers, hinges = model.box_centers, model.joint_positions
        shapes = self._collision_shapes(physics, fillet.mesh, model)
        origin = fillet.state[0, :3] - centers[0]
        parents = [centers[0]] + [hinges[i - 2] for i in range(2, n)]
        identity = [0.0, 0.0, 0.0, 1.0]
        body = p.createMultiBody(
            baseMass=float(model.masses[0]),
            baseCollisionShapeIndex=shapes[0],
            basePosition=(origin + centers[0]).tolist(),
            baseOrientation=identity,
            linkMasses=model.masses[1:].tolist(),
            linkCollisionShapeIndices=shapes[1:],
            linkVisualShapeIndices=[-1] * (n - 1),
            linkPositions=[(hinges[i - 1] - parents[i - 1]).tolist() for i in range(1, n)],
            linkOrientations=[identity] * (n - 1),
            linkInertialFramePositions=[(centers[i] - hinges[i - 1]).tolist() for i in range(1, n)],
            linkInertialFrameOrientations=[identity] * (n - 1),
            linkParentIndices=list(range(n - 1)),
            linkJointTypes=[p.JOINT_REVOLUTE] * (n - 1),
            linkJointAxis=[[0.0, 1.0, 0.0]] * (n - 1),
            physicsClientId=c,
        )
        inertias = segment_inertias(model, self.config.inertia_floor)
        fillet.inertias, fillet.joint_offsets = inertias, centers[1:] - hinges
        for link in range(-1, n - 1):
            limits = {} if link < 0 else {"jointLowerLimit": -JOINT_LIMIT, "jointUpperLimit": JOINT_LIMIT}
            if self.config.island_sleeping:
                limits["activationState"] = p.ACTIVATION_STATE_ENABLE_SLEEPING
            p.changeDynamics(
                body, link, localInertiaDiagonal=inertias[link + 1].tolist(), lateralFriction=1.0, restitution=0.0,
                linearDamping=0.0, angularDamping=0.0, physicsClientId=c, **limits,
            )
        # pybullet gives every joint a velocity motor that acts as friction; switch them off
        p.setJointMotorControlArray(
            body, list(range(n - 1)), p.VELOCITY_CONTROL, forces=[0.0] * (n - 1), physicsClientId=c
        )
        for link in range(-1, n - 1):
            p.setCollisionFilterGroupMask(body, link, FILLET_COLLISION_GROUP, FILLET_COLLISION_MASK,
                                          physicsClientId=c)
        p.resetBaseVelocity(body, [fillet.speed, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=c)
        fillet.body, fillet.physics = body, physics
        physics.built += 1
        physics.live += 1
        fillet.activation_time = self.time
        self._read_state(fillet)

    def remove(self, fillet_id: int) -> None:
        """Take a fillet off the line now (it is reported by :meth:`take_removed`)."""
        fillet = self._fillets.pop(fillet_id)
        if fillet.body >= 0:
            p.removeBody(fillet.body, physicsClientId=fillet.physics.client)
            fillet.physics.live -= 1
        self._removed.append(fillet_id)

    @property
    def steps(self) -> int:
        """Physics steps taken so far (``time`` is ``steps * config.dt``)."""
        return self._steps

    def start_at(self, step: int) -> None:
        """Start a new world's clock at ``step`` of a running line (a worker world that joins it late), instead of
        stepping an empty world there."""
        if self._steps or self._fillets or step < 0:
            raise ValueError(f"only a new world's clock can be started, at a step >= 0 (got {step})")
        self._steps = int(step)
        self.time = self._steps * self.config.dt

    def plan(self, until: float) -> None:
        """Nothing to do: a single world steps all its fillets itself (the interface of
        :meth:`~woody_sim.split_world.SplitLineWorld.plan`, which starts its worker on the steps to ``until``)."""

    def take_removed(self) -> list[int]:
        """Ids removed since the last call (fallen, left the line, or :meth:`remove`d)."""
        removed, self._removed = self._removed, []
        return removed

    @property
    def fillets(self) -> dict[int, FilletInfo]:
        """Metadata of the live fillets by id."""
        return {fid: fillet.info for fid, fillet in self._fillets.items()}

    def model(self, fillet_id: int) -> FilletModel:
        """The chain model (boxes, masses, hinges, visuals) of a live fillet."""
        return self._fillets[fillet_id].model

    def is_dynamic(self, fillet_id: int) -> bool:
        """True once the fillet is a pybullet chain (near or past the roller edge)."""
        return self._fillets[fillet_id].body >= 0

    # ------------------------------------------------------------------ stepping

    def step(self) -> float:
        """Advance one physics step of ``config.dt``; returns the sim time."""
        cfg = self.config
        margin = cfg.activation_margin
        self._apply_speed_changes()
        for fillet in self._fillets.values():
            if fillet.body < 0 and margin is not None and self._leading_x(fillet) >= -margin:
                self._activate(fillet)
        dynamic = [f for f in self._fillets.values() if f.body >= 0]
        self._update_drive(dynamic)
        for fillet in dynamic:
            self._apply(fillet)
        for physics in self._physics:
            if physics.live:
                p.stepSimulation(physicsClientId=physics.client)
        self._steps += 1
        self.time = self._steps * cfg.dt
        for fillet in self._fillets.values():
            if fillet.body >= 0:
                self._read_state(fillet)
            else:
                self._kinematic_state(fillet)
        self._remove_finished()
        self._close_emptied()
        return self.time

    def _close_emptied(self) -> None:
        """Close every world but the newest once its last chain is gone (its memory goes with it)."""
        closed = [physics for physics in self._physics[:-1] if not physics.live]
        for physics in closed:
            physics.close()
        if closed:
            self._physics = [physics for physics in self._physics if physics.client >= 0]
            return_freed_memory()

    def _apply(self, fillet: _Fillet) -> None:
        """Hinge spring-damper and belt drive forces for the coming step."""
        c = fillet.physics.client
        theta, rate = hinge_state(fillet.state)
        joints = list(range(fillet.model.n_segments - 1))
        torque = self._implicit_torque(fillet, theta, rate)
        fillet.torque = torque
        fillet.rate = rate
        p.setJointMotorControlArray(fillet.body, joints, p.TORQUE_CONTROL, forces=torque.tolist(), physicsClientId=c)
        driven = np.flatnonzero(fillet.drive.any(axis=1))
        for i, force, point in zip(driven.tolist(), fillet.drive[driven].tolist(), fillet.state[driven, :3].tolist()):
            p.applyExternalForce(fillet.body, i - 1, force, point, p.WORLD_FRAME, physicsClientId=c)

    def _implicit_torque(self, fillet: _Fillet, theta: np.ndarray, rate: np.ndarray) -> np.ndarray:
        """Backward-Euler hinge torques (:func:`~woody_sim.hinge_law.implicit_hinge_torque`) from the chain's
        mass matrix in its current pose (:func:`~woody_sim.hinge_law.chain_mass_matrix`; pybullet's
        ``calculateMassMatrix`` agrees in the joint block once the base is eliminated, but only until a world
        removes a chain, after which it can return another chain's: docs/physics.md)."""
        cfg = self.config
        mass = chain_mass_matrix(fillet.state, fillet.model.masses, fillet.inertias, fillet.joint_offsets)
        scale = cfg.hinge_scale
        return implicit_hinge_torque(mass, theta, rate, fillet.rate, fillet.torque, fillet.info.k * scale,
                                     cfg.damping * scale, cfg.dt)

    def _update_drive(self, dynamic: list[_Fillet]) -> None:
        """The seed's belt drive on every touching segment (:func:`~woody_sim.belt_drive.belt_drive`).

        The force may not exceed mu_static N (else it slides at mu_dynamic N), N
        being the segment's low-pass filtered contact normal force, so a segment
        the roller no longer presses on gets no drive.
        """
        cfg = self.config
        blend = min(1.0, cfg.dt / cfg.normal_force_tau)
        contacts = {physics: _conveyor_contacts(physics) for physics in self._physics if physics.live}
        for fillet in dynamic:
            rows = contacts[fillet.physics]
            mine = rows[rows[:, 0] == fillet.body]
            belt_drive(mine[:, 1].astype(np.int64), mine[:, 2:], fillet.state[:, 7:10], fillet.model.masses,
                       fillet.speed, cfg.dt, blend, cfg.friction_static, cfg.friction_dynamic,
                       fillet.normal_force, fillet.drive)

    def _read_state(self, fillet: _Fillet) -> None:
        """One batched query for every link's pose and velocity (segment frames = centre-of-mass frames)."""
        c = fillet.physics.client
        pos, orn = p.getBasePositionAndOrientation(fillet.body, physicsClientId=c)
        lin, ang = p.getBaseVelocity(fillet.body, physicsClientId=c)
        links = p.getLinkStates(
            fillet.body, list(range(fillet.model.n_segments - 1)),
            computeLinkVelocity=1, computeForwardKinematics=1, physicsClientId=c,
        )
        rows = [pos + orn + lin + ang] + [s[0] + s[1] + s[6] + s[7] for s in links]
        fillet.state = np.fromiter(itertools.chain.from_iterable(rows), float, 13 * len(rows)).reshape(-1, 13)

    def _remove_finished(self) -> None:
        """Drop chains that blew up (too fast or non-finite: see ``blown_up``), fell, left the line or got stuck.

        Only pybullet chains are checked: a fillet on the belt fast path moves analytically.
        """
        for fid, fillet in list(self._fillets.items()):
            if fillet.body < 0:
                continue
            fate = chain_fate(fillet.state, fillet.model.masses, self.geometry.remove_z)
            if fate == BLOWN_UP:
                self.blown_up.append(fid)
                self.remove(fid)
            elif fate == FINISHED or self.time - fillet.activation_time > DYNAMIC_TIMEOUT:
                self.remove(fid)

    # ------------------------------------------------------------------ queries

    def segment_poses(self) -> dict[int, np.ndarray]:
        """For each live fillet, (N, 7) [x, y, z, qx, qy, qz, qw] of its segment frames in the world frame."""
        return {fid: fillet.state[:, :7].copy() for fid, fillet in self._fillets.items()}

    @staticmethod
    def _com(fillet: _Fillet) -> np.ndarray:
        return fillet.model.masses @ fillet.state[:, :3] / fillet.model.masses.sum()

    def center_of_mass(self, fillet_id: int) -> np.ndarray:
        """World position (3,) of a live fillet's centre of mass."""
        return self._com(self._fillets[fillet_id])

    def segment_velocities(self, fillet_id: int) -> np.ndarray:
        """(N, 3) world linear velocity of each segment's centre of mass."""
        return self._fillets[fillet_id].state[:, 7:10].copy()

    def hinge_angles(self, fillet_id: int) -> np.ndarray:
        """(N - 1,) hinge angles (rad); positive when the downstream segment pitches down."""
        return hinge_state(self._fillets[fillet_id].state)[0]


def check_spawn(geometry: LineGeometry, k: float, lane: int, mass: float, speed_mps: float
                ) -> tuple[float, int, float, float]:
    """(k, lane, mass, speed) of a spawn request as numbers, or a ValueError that says what is wrong."""
    k = float(k)
    if not math.isfinite(k) or k < 0.0:
        raise ValueError(f"stiffness k must be a finite number >= 0, got {k}")
    mass = _check_positive_finite("mass", mass)
    if mass > MAX_MASS:
        raise ValueError(f"mass must be at most {MAX_MASS} kg, got {mass}")
    speed = _check_speed(speed_mps)
    if isinstance(lane, bool) or not isinstance(lane, (int, np.integer)):
        raise ValueError(f"lane must be an integer, got {lane!r}")
    geometry.lane_y(int(lane))  # raises for a lane the line does not have
    return k, int(lane), mass, speed


def _check_speed(speed_mps: float) -> float:
    speed = _check_positive_finite("speed", speed_mps)
    if speed > MAX_SPEED_MPS:
        raise ValueError(f"speed must be at most {MAX_SPEED_MPS:.3f} m/s (is it in FPM?), got {speed}")
    return speed


def check_lateral_offset(lateral_offset: float) -> float:
    """The offset (m) of a fillet from its lane centre as a number, or a ValueError."""
    offset = float(lateral_offset)
    if not math.isfinite(offset):
        raise ValueError(f"lateral offset must be a finite number of metres, got {lateral_offset!r}")
    return offset


def check_fillet_id(fillet_id: int, live: Container[int]) -> int:
    """``fillet_id`` as an int, or a ValueError if it is not a non-negative integer or is in ``live``."""
    if isinstance(fillet_id, bool) or not isinstance(fillet_id, (int, np.integer)) or fillet_id < 0:
        raise ValueError(f"fillet_id must be a non-negative integer, got {fillet_id!r}")
    if fillet_id in live:
        raise ValueError(f"fillet_id {fillet_id} is already on the line")
    return int(fillet_id)


KEEP, BLOWN_UP, FINISHED = 0, 1, 2
"""What :func:`chain_fate` says of a chain."""


@numba.njit(cache=True, nogil=True)
def chain_fate(state: np.ndarray, masses: np.ndarray, remove_z: float) -> int:
    """BLOWN_UP (a non-finite value or a segment faster than BLOWUP_SPEED in any axis), FINISHED (every segment
    below ``remove_z``, or the centre of mass past PAST_ROLLER_X) or KEEP, for a chain's (N, 13) state; one
    compiled pass, as it runs for every chain at every step."""
    for value in state.ravel():
        if not math.isfinite(value):
            return BLOWN_UP
    for i in range(state.shape[0]):
        for j in range(7, 10):
            if abs(state[i, j]) > BLOWUP_SPEED:
                return BLOWN_UP
    fallen = True
    moment = 0.0
    for i in range(state.shape[0]):
        fallen = fallen and state[i, 2] < remove_z
        moment += masses[i] * state[i, 0]
    return FINISHED if fallen or moment / masses.sum() > PAST_ROLLER_X else KEEP
