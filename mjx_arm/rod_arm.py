"""The reference Cosserat rod as an arm: `Arm.rollout`'s interface, in the chain's domains.

`load_rod(domain)` returns a `RodArm` whose `rollout(pressures_bar)` takes the programs
`mjx_arm.Arm.rollout` takes ([T, 3] or [B, T, 3] chamber commands in bar at 10 Hz, each held for
0.1 s) and returns the same poses ([T, 6] or [B, T, 6]: tip position in m, then the unit d3 of
the last element), from the same rest (settled under gravity with the chambers at the valve
floor) through the same valves (`mjx_arm.valve`: saturation to [0.2, 3.5] bar, 0.2 s rise and
0.56 s drop time constants). So any pressure program can be scored in the paper's own kind of
simulator, a rod under Gazzola's law, as well as on the fitted chain.

The rollout is `mjx_arm.cosserat`'s (`mjx_arm.rod_dynamics.rollout_single`: position Verlet at the
paper code's 2e-4 s, its analytical damper), jitted and vmapped over the batch, compiled once per
domain, dtype and program shape. In float64 (the default) it is the committed reference path
that `mjx_arm.fidelity` and `mjx_arm.fit` call, to rounding; `python -m mjx_arm.rod_check`
checks that on the fidelity report's programs. float32 (`dtype="float32"`) is offered for speed;
`bench.rod_throughput` measures what it costs in accuracy and gains in speed
(bench/results/cpu/rod_throughput.md).

Domains map onto the rod as follows (`rod_params`):
  * medium: `Domain.viscosity_scale` multiplies the rod's damping constant c of the source
    medium (800 1/s, the paper code's D_s); None, the chain's fitted constrained medium, is the
    paper code's D_c (c = 8000 1/s), which that fit was made against. A `Domain.viscosity` in Pa s
    has no meaning for the rod's damper and is refused.
  * `stiffness_scale` multiplies E and G (the aged arm: x0.7 in D_c); `mass_scale` the mass,
    and with it every element's inertia.
  * `inertia_scale` is the chain's numerical mass scaling for its explicit drag; the rod's
    damper is unconditionally stable and needs none, so it is ignored.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from mjx_arm import checks, cosserat, domains, valve
from mjx_arm.arm import SimulationDivergedError
from mjx_arm.model_gen import ArmParams
from mjx_arm.rod_dynamics import rollout_single
from mjx_arm.rod_params import DOMAIN_DAMPING_PER_S, CosseratParams, RodState, make_rod

#: The rollout's floating-point types; float64 is the default (see `RodArm`).
DTYPES = ("float64", "float32")
#: What `RodArm.rollout` accepts as `backend` (`Arm.rollout`'s keyword): the rod's one simulator.
BACKENDS = (None, "rod")
#: Largest tip difference (fraction of L) allowed between `RodArm` in float64 and the committed
#: reference path (`cosserat.rollout`) by `python -m mjx_arm.rod_check` and the tests.
AGREEMENT_FRACTION_OF_L = 1e-6
#: Physics steps per loop iteration by JAX backend when `RodArm.unroll` is None
#: (bench/results/h200/rod_unroll: 10 gives 1.25-1.36x at batches 1-512 on one H200).
DEFAULT_UNROLL = {"gpu": 10, "cpu": 1}
#: Trajectories per host CPU device in one call when the rod runs on the host's cores
#: (`host_devices`): 4 per device ran 1.5x the simulated s per core of 1 per device on a 2-core
#: CPU, and 8 no better (SIMD across the batch; bench.rod_host, bench/results/cpu/rod_host).
HOST_BATCH_PER_DEVICE = 4
#: Most trajectories in one rod call on an accelerator: one H200 runs the rod at ~1,090 simulated
#: s/s at batch 512 and ~400 at 64 (nearly the time of one trajectory up to ~64), so larger
#: batches buy little and cost memory (512 x 1,200 periods of float64 poses are ~30 MB).
ACCELERATOR_BATCH = 512
#: The XLA flag that gives JAX several host CPU devices (set before JAX starts).
HOST_DEVICES_FLAG = "--xla_force_host_platform_device_count"


def host_devices() -> list:
    """The host's CPU devices that the rod splits its batches over, or [] for JAX's default device.

    The rod is latency-bound (500 sequential float64 steps per 0.1 s period): processes sharing one
    GPU time-slice it (bench/results/h200/rod_sharing: the sum stays at one process's ~70
    simulated s/s), while each host core runs one at ~28 (16 cores: 342 summed). So when JAX has
    more than one CPU device, which it has only when `HOST_DEVICES_FLAG`=N is in XLA_FLAGS before it
    starts (`experiments.paper` sets N to the usable cores for its stages on an accelerator), every
    `RodArm.rollout` shards its batch across them, one thread each, whatever the default backend.
    """
    try:
        cpus = jax.devices("cpu")
    except RuntimeError:  # JAX_PLATFORMS without the CPU
        return []
    return cpus if len(cpus) > 1 else []


def rod_params(
    domain: str | domains.Domain = "source",
    arm: ArmParams = ArmParams(),
    n_elements: int = 20,
) -> CosseratParams:
    """The rod of `arm`'s geometry, section, mass and material in `domain` (see the module
    docstring for the mapping). For "source" and "constrained" these are exactly the
    parameters the fidelity report runs (`CosseratParams.from_arm(arm, domain)`).

    Raises:
      ValueError: an unknown domain name, or a `Domain` with `viscosity` set.
    """
    d = domains.resolve(domain)
    if d.viscosity is not None:
        raise ValueError(
            f"Domain {d.name!r} sets viscosity={d.viscosity} Pa s, which the rod's damper has no"
            " use for: give viscosity_scale (a factor on the source medium's damping constant"
            f" {DOMAIN_DAMPING_PER_S['source']:g} 1/s) instead"
        )
    base = CosseratParams.from_arm(arm, "source", n_elements=n_elements)
    damping = (
        DOMAIN_DAMPING_PER_S["constrained"]
        if d.viscosity_scale is None
        else base.damping_per_s * d.viscosity_scale
    )
    return dataclasses.replace(
        base,
        damping_per_s=damping,
        youngs_modulus_pa=base.youngs_modulus_pa * d.stiffness_scale,
        shear_modulus_pa=base.shear_modulus_pa * d.stiffness_scale,
        mass_kg=base.mass_kg * d.mass_scale,
    )


@functools.lru_cache(maxsize=16)
def _batched_rollout(
    params: CosseratParams, dtype: str, valve_params: valve.ValveParams, unroll: int = 1
):
    """jit(vmap(rollout_single)) of one rod in `dtype`: commands [B, T, 3] -> poses [B, T, 6]."""
    rod = make_rod(params).astype(dtype)
    rest = RodState(*(np.asarray(a, dtype) for a in cosserat.rest_state(params)))
    bound = functools.partial(
        rollout_single, rod, params.n_substeps, valve_params, rest, unroll=unroll
    )

    def single(commands):
        # Full float32 products: JAX's default lets XLA use TensorFloat32 (a 10-bit mantissa) for
        # float32 matrix products on NVIDIA GPUs, as `mjx_arm.arm.mjx_precision` says for the
        # chain. No effect on CPUs or in float64.
        with jax.default_matmul_precision("highest"):
            return bound(commands)

    return jax.jit(jax.vmap(single))


@dataclasses.dataclass(frozen=True)
class RodArm:
    """The reference rod in one domain, with `Arm.rollout`'s interface.

    Attributes:
      params: the rod (`rod_params` of the domain).
      domain: the domain it was made for.
      dtype: "float64" (default: the reference, to rounding) or "float32" (faster, less exact).
      valve: the valve constants, the chain's defaults (`mjx_arm.valve.ValveParams`).
      model_hash: "rod-" and 16 hex digits of sha256 over the arm's physical values and the
        element count, the same in every domain (as `Arm.model_hash` is one MJCF's): what a
        translator trained on the rod's data records as its arm.
      unroll: physics steps per iteration of the compiled step loop (the same arithmetic, to
        1e-15 of L). None: `DEFAULT_UNROLL` for the default JAX backend, measured by
        `bench.rod_unroll` (bench/results/h200/rod_unroll: 1.3x at batches 64-512 on one H200 at
        10; on a 2-core CPU unrolling made it 1.6-2.4x slower).
    """

    params: CosseratParams
    domain: domains.Domain
    dtype: str = "float64"
    valve: valve.ValveParams = valve.ValveParams()
    unroll: int | None = None
    model_hash: str = ""

    def __post_init__(self):
        if self.dtype not in DTYPES:
            raise ValueError(f"dtype must be one of {DTYPES}, got {self.dtype!r}")
        if self.unroll is not None and (
            isinstance(self.unroll, bool) or not isinstance(self.unroll, int) or self.unroll < 1
        ):
            raise ValueError(f"unroll must be None or an int >= 1, got {self.unroll!r}")
        self.params.validate()
        valve.check(self.valve)

    @property
    def n_substeps(self) -> int:
        """Physics steps per 0.1 s control period (500 at the paper code's 2e-4 s)."""
        return self.params.n_substeps

    @property
    def timestep_s(self) -> float:
        return self.params.timestep_s

    @property
    def length_m(self) -> float:
        return self.params.length_m

    def rest_pose(self) -> np.ndarray:
        """The pose [6] every rollout starts from (float64)."""
        state = cosserat.rest_state(self.params)
        return np.concatenate([state.x[-1], state.q[-1, 2]])

    def placement(self) -> str:
        """Where `rollout` runs: "host" (split over `host_devices`) or JAX's default backend."""
        return "host" if host_devices() else jax.default_backend()

    def call_size(self) -> int | None:
        """The batch one rollout call should take to use the machine, for callers that split or pad
        many trajectories (`tracking.held.rollout_grouped`, `mjx_arm.babble.rod`): on the host's
        devices `HOST_BATCH_PER_DEVICE` per device; on an accelerator `ACCELERATOR_BATCH` (a call
        costs about its longest trajectory up to ~64); None on one CPU device (cost ~ total
        simulated time, so no padding pays)."""
        where = self.placement()
        if where == "host":
            return HOST_BATCH_PER_DEVICE * len(host_devices())
        return None if where == "cpu" else ACCELERATOR_BATCH

    def rollout_fn(self):
        """The jitted, vmapped rollout `fn(commands [B, T, 3]) -> poses [B, T, 6]` in `dtype`.

        Commands must already be in `dtype` (float64 ones need `jax.enable_x64(True)` around the
        call) and on their device; no checks are made. `rollout` is the checked entry point.
        """
        where = self.placement()
        unroll = self.unroll or DEFAULT_UNROLL.get("cpu" if where == "host" else where, 1)
        return _batched_rollout(self.params, self.dtype, self.valve, unroll)

    def rollout(self, pressures_bar, backend: str | None = None) -> np.ndarray:
        """Simulates pressure programs from rest and returns the tip pose after each command.

        As `mjx_arm.Arm.rollout`: commands outside [0, 3.5] bar saturate like a real valve and
        commands under the valve floor (0.2 bar) act as the floor; each is held for 0.1 s while
        the chamber pressures lag toward it. The pose is the rod's at the end of each period.

        Args:
          pressures_bar: [T, 3] or [B, T, 3] chamber commands (bar) at 10 Hz.
          backend: None or "rod", so that code written for `Arm.rollout(p, backend=...)` (e.g.
            `tracking.held.rollout_grouped`) runs the rod too; the rod has one simulator (JAX,
            on JAX's default device or the host's, `host_devices`), so the chain's "c" and
            "mjx" are refused rather than silently run in the rod.

        Returns:
          [T, 6] or [B, T, 6] float64 poses: tip position (m) then unit d3.

        Raises:
          ValueError: bad shape (an empty batch included), boolean or non-finite pressures, or
            a backend other than None or "rod".
          SimulationDivergedError: a trajectory's pose became non-finite.
        """
        if backend not in BACKENDS:
            raise ValueError(
                f"backend {backend!r}: the reference rod runs only its own JAX simulator; give"
                " backend=None or 'rod' ('c' and 'mjx' are the chain's, mjx_arm.Arm.rollout)"
            )
        if np.asarray(pressures_bar).dtype == np.bool_:
            raise ValueError("pressures_bar is boolean; give pressures in bar (numbers)")
        batched = checks.check_pressures(pressures_bar)
        with jax.enable_x64(self.dtype == "float64"):
            poses = np.asarray(self.rollout_fn()(_placed(batched, self.dtype)), np.float64)
        poses = poses[: len(batched)]
        ok = np.isfinite(poses).all(axis=-1)  # [B, T]
        if not ok.all():
            bad = np.flatnonzero(~ok.all(axis=1))
            first = np.argmin(ok[bad], axis=1)
            raise SimulationDivergedError(
                f"the rod diverged in {len(bad)} of {len(ok)} trajectories (first: trajectory"
                f" {bad[0]} at period {first[0]}); in float32, try dtype='float64'",
                bad,
                first,
            )
        return poses if np.ndim(pressures_bar) == 3 else poses[0]


def _placed(batched: np.ndarray, dtype: str):
    """Commands [B, T, 3] as a JAX array where the rod runs: on JAX's default device, or split
    over `host_devices` along the batch (padded to a multiple of their number by repeating the
    last program; each trajectory is simulated on its own, so its poses do not depend on the
    split, and the caller drops the padded rows)."""
    devices = host_devices()
    if not devices:
        return jnp.asarray(batched, dtype)
    pad = -len(batched) % len(devices)
    if pad:
        batched = np.concatenate([batched, np.repeat(batched[-1:], pad, axis=0)])
    sharding = NamedSharding(Mesh(np.asarray(devices), ("batch",)), PartitionSpec("batch"))
    return jax.device_put(np.asarray(batched, dtype), sharding)


def load_rod(
    domain: str | domains.Domain = "source",
    *,
    dtype: str = "float64",
    arm: ArmParams = ArmParams(),
    n_elements: int = 20,
) -> RodArm:
    """The reference rod as an arm in `domain` ("source", "constrained", "aged" or a `Domain`).

    Args:
      domain: the world, mapped onto the rod as the module docstring says.
      dtype: "float64" (default) or "float32".
      arm: the geometry, section, mass and material (its physical values, not its fit).
      n_elements: Cosserat elements (the paper's 20).

    Raises:
      ValueError: an unknown domain or dtype, a `Domain` with `viscosity` set, or a rod that is
        unstable at its timestep (`CosseratParams.validate`).
    """
    digest = hashlib.sha256(f"{arm!r} n_elements={n_elements}".encode()).hexdigest()[:16]
    return RodArm(
        params=rod_params(domain, arm, n_elements),
        domain=domains.resolve(domain),
        dtype=dtype,
        model_hash=f"rod-{digest}",
    )
