"""Motor babbling: pseudo-random pressure programs, simulated in parallel, saved as datasets.

Each chamber independently jumps to a uniform random target in [0, 3.5] bar and holds it for a
uniform random whole number of 0.1 s control periods in [0.5, 3] s; the three chambers switch at
different times, so the programs visit the whole pressure cube and hence the workspace. Every
trajectory starts from the arm's rest state (the paper resets the arm between trajectories).

Programs are reproducible: trajectory i of a (domain, split) stream is drawn by a NumPy
Generator seeded with ``[seed, stream_id(domain, split), i]`` (`mjx_arm.programs.babble_programs`,
the programs' one home), so it does not depend on the batch, chunk, backend or device count.
(NumPy rather than jax.random: each new batch shape would cost a JAX compilation of seconds on a
small CPU, and the programs are a negligible cost.)

Command line (`mjx_arm.babble.cli`; writes ``<out>/<domain>_<split>.npz`` and
``<out>/manifest.json`` as a whole folder, replacing an earlier run's folder only once every file
is written; see `mjx_arm.dataset`)::

    python -m mjx_arm.babble --preset paper --out data/babble          # 50 + 3 x 60 s, both domains
    python -m mjx_arm.babble --domain source --n 1000 --duration 10 --chunk 4096 --backend mjx

Validation trajectories go to a separate file per domain (``<domain>_val.npz``) with their own
random stream. With ``--domain both`` the task-space bounds stored in every file are the per-axis
min/max over both domains' train and validation poses (the paper's normalisation); with one
domain, over that domain's data only (use `dataset.workspace_bounds` and `Dataset.with_bounds` to
share bounds later).

Parallelism. With ``--backend mjx`` each chunk of programs is one jitted, vmapped rollout, its
batch axis sharded over every device with a `NamedSharding` on a 1-D ``("batch",)`` mesh; chunks
are padded to a multiple of the device count (and all to the same size, so there is one compile).
``--backend c`` runs MuJoCo C `mujoco.rollout` on all CPU cores; ``auto`` picks ``c`` when JAX's
default backend is the CPU (MJX on CPU is far slower than MuJoCo C) and ``mjx`` otherwise.
``--backend rod`` simulates the same programs in the reference Cosserat rod instead of the chain
(`mjx_arm.load_rod`, float64; `mjx_arm.babble.rod`: its batches and cost, ~100-1,000x the
chain's); its files carry the rod's model hash and ``"simulator": "rod"``, and it takes no MJCF.

Multi-host. Start the same command on every host with ``--distributed --backend mjx`` and
``--coordinator HOST:PORT --num-processes N --process-id I`` (I = 0 .. N-1; process 0 runs the
coordinator). Without those options `jax.distributed.initialize()` takes them from the cluster
(SLURM, Open MPI, TPU pods); of plain environment variables jax 0.10 reads only
``JAX_COORDINATOR_ADDRESS``, not a process count or id. The mesh then spans all global devices;
every process checks that all have the same options, model and programs, builds only its own
shards of them with `jax.make_array_from_callback`, the poses are gathered with
`multihost_utils.process_allgather`, and process 0 alone writes the files. The data equal, bit
for bit, a one-process run over as many devices (tests/test_multiprocess.py, docs/multihost.md).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import math
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P
from mujoco import mjx

from mjx_arm import arm as arm_lib
from mjx_arm import compile_notice, constants, dataset, domains
from mjx_arm.babble import rod as rod_babble
from mjx_arm.babble.memory import (  # noqa: F401  (the memory check; re-exported)
    C_BYTES_PER_TRAJECTORY,
    MEMORY_FRACTION,
    NotEnoughMemoryError,
    available_memory_bytes,
    check_memory,
    largest_n_train,
    memory_estimate_bytes,
)
from mjx_arm.programs import babble_programs, shape_like_programs

#: "rod" is the reference rod (`mjx_arm.babble.rod`), the others the chain's simulators.
BACKENDS = ("auto", "mjx", "c", "rod")
#: Largest MuJoCo C batch per call, `Arm.rollout`'s own (see `mjx_arm.arm.C_CHUNK`).
C_MAX_CHUNK = arm_lib.C_CHUNK


#: The program families `BabbleConfig.programs` can name.
PROGRAM_FAMILIES = ("babbling", "shape_like")


def family_programs(config: BabbleConfig, n: int, domain: str, split: str) -> np.ndarray:
    """The first n programs [n, T, 3] (bar, float32) of a (domain, split) stream of the
    config's family; each domain and split has its own stream (the domains are unpaired)."""
    if config.programs == "shape_like":
        return shape_like_programs(
            n, config.n_steps / constants.CONTROL_HZ, config.seed, split=f"babble/{domain}/{split}"
        )
    return babble_programs(config, np.arange(n), domain=domain, split=split)


@dataclasses.dataclass(frozen=True)
class BabbleConfig:
    """Options of a babbling run. Defaults are the paper's (50 + 3 trajectories of 60 s).

    Its program fields make it the `mjx_arm.programs.BabbleSpec` that `babble_programs` draws
    from."""

    seed: int = 0
    """Root seed of every pressure program."""
    n_train: int = 50
    """Training trajectories per domain [paper: 50]."""
    n_val: int = 3
    """Validation trajectories per domain, in a separate file [paper: 3]."""
    duration_s: float = 60.0
    """Length of each trajectory (s) [paper: 60 s]."""
    p_low_bar: float = 0.0
    """Lowest target pressure (bar); commands under the 0.2 bar valve floor act as the floor."""
    p_high_bar: float = constants.P_MAX_BAR
    """Highest target pressure (bar) [paper: 3.5 bar]."""
    hold_min_s: float = 0.5
    """Shortest hold of one target (s)."""
    hold_max_s: float = 3.0
    """Longest hold of one target (s)."""
    domains: tuple[str | domains.Domain, ...] = ("source", "constrained")
    """Domains to simulate: `mjx_arm.DOMAINS` names, or `Domain`s of other names (a medium off
    the paper's pair, e.g. from `--domain-file`), each babbled in its own programs' stream
    named by its name."""
    backend: str = "auto"
    """"mjx", "c" (MuJoCo C on all CPU cores), "auto" (c when JAX runs on the CPU) or "rod"
    (the reference Cosserat rod, float64, instead of the chain: `mjx_arm.babble.rod`)."""
    chunk: int = 4096
    """Trajectories simulated at once (over all devices); bounds device memory."""
    programs: str = "babbling"
    """The program family: "babbling" (held random targets, the paper's) or "shape_like"
    (`mjx_arm.programs.shape_like_programs`: random ellipses, polygons, staircases and phase
    jumps, never a test shape; the hold and pressure-range fields are then unused)."""

    def __post_init__(self):
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.programs not in PROGRAM_FAMILIES:
            raise ValueError(f"programs must be one of {PROGRAM_FAMILIES}, got {self.programs!r}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0 (NumPy seeds), got {self.seed}")
        if min(self.n_train, self.n_val) < 0 or self.n_train + self.n_val == 0:
            raise ValueError("n_train and n_val must be >= 0, not both 0")
        names = [domains.resolve(d).name for d in self.domains]  # unknown names raise
        if not names or len(set(names)) != len(names):
            raise ValueError(f"need one or more distinct domains, got {names}")
        for d in self.domains:
            if isinstance(d, domains.Domain) and d.name in domains.DOMAINS:
                if d != domains.DOMAINS[d.name]:
                    raise ValueError(
                        f"a Domain named {d.name!r} with other fields than the built-in one:"
                        " give the other medium its own name"
                    )
            if isinstance(d, domains.Domain) and self.backend == "rod":
                raise ValueError("backend 'rod' babbles the rod's own media only, by name")
        if self.n_steps < 1 or self.chunk < 1:
            raise ValueError("duration_s must cover at least one control period; chunk >= 1")
        if not 0 < self.hold_min_steps <= self.hold_max_steps:
            raise ValueError("need 0 < hold_min_s <= hold_max_s (at least one control period)")
        if not self.p_low_bar <= self.p_high_bar:
            raise ValueError("need p_low_bar <= p_high_bar")

    @property
    def n_steps(self) -> int:
        """Control periods per trajectory (T)."""
        return int(round(self.duration_s * constants.CONTROL_HZ))

    @property
    def hold_min_steps(self) -> int:
        return int(round(self.hold_min_s * constants.CONTROL_HZ))

    @property
    def hold_max_steps(self) -> int:
        return int(round(self.hold_max_s * constants.CONTROL_HZ))

    def splits(self) -> dict[str, int]:
        """Split name -> number of trajectories (splits with none are left out)."""
        return {k: n for k, n in (("train", self.n_train), ("val", self.n_val)) if n > 0}


#: The paper's data: 50 training and 3 validation trajectories of 60 s in each domain.
PAPER = BabbleConfig()

# ---------------------------------------------------------------------------------- rollouts


def resolve_backend(backend: str) -> str:
    """ "auto" -> "c" when JAX runs on the CPU, else "mjx" (never "rod": the rod is asked for by
    name); other names pass through."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "c" if jax.default_backend() == "cpu" else "mjx"
    return backend


def batch_mesh(devices: Sequence[jax.Device] | None = None) -> Mesh:
    """A 1-D mesh with axis "batch" over `devices` (default: every device of every host)."""
    return Mesh(np.asarray(devices if devices is not None else jax.devices()), ("batch",))


def padded_size(n: int, n_devices: int) -> int:
    """Smallest multiple of `n_devices` that is >= n (and >= n_devices)."""
    return max(1, math.ceil(n / n_devices)) * n_devices


class ShardedRollout:
    """A jitted, vmapped MJX rollout whose batch axis is sharded over a 1-D device mesh.

    Call it with commands [B, T, 3] (bar, B any size): it pads B to a multiple of the device
    count, runs, and returns (poses [B, T, 6] float32 numpy, ok [B, T] bool numpy).

    The rest state is an argument of the jitted function, not a constant baked into it, so arms
    that differ only in domain (same MJCF structure) share one compilation.
    """

    def __init__(self, arm: arm_lib.Arm, devices: Sequence[jax.Device] | None = None):
        self.arm = arm
        self.mesh = batch_mesh(devices)
        self.n_devices = self.mesh.devices.size
        self.batch_sharding = NamedSharding(self.mesh, P("batch"))
        replicated = NamedSharding(self.mesh, P())
        self.mjx_model, self.rest = _replicate(
            (_local_mjx_model(arm), (arm.rest_qpos, arm.rest_qvel)), replicated
        )
        self.fn = _sharded_fn(
            tuple(self.mesh.devices.flat),
            arm.tip_site_id,
            tuple(int(i) for i in arm.actuator_ids),
            arm.n_substeps,
            arm.valve,
            arm.chamber_controls,
        )

    def shard(self, commands_bar: np.ndarray) -> jax.Array:
        """Commands [B, T, 3] (B a multiple of the device count) -> a global sharded array.

        Each process materialises only the shards of its own devices (multi-host safe, given
        every process holds the same `commands_bar`).
        """
        commands_bar = np.asarray(commands_bar, np.float32)
        return jax.make_array_from_callback(
            commands_bar.shape, self.batch_sharding, lambda index: commands_bar[index]
        )

    def pad(self, commands_bar: np.ndarray, size: int | None = None) -> np.ndarray:
        """Pads [B, T, 3] to [size, T, 3] (default: the next multiple of the device count) by
        repeating the last program; the padded rows are simulated and dropped."""
        n = commands_bar.shape[0]
        size = padded_size(n, self.n_devices) if size is None else size
        if size % self.n_devices or size < n:
            raise ValueError(f"pad size {size} must be >= {n} and a multiple of {self.n_devices}")
        return np.concatenate([commands_bar, np.repeat(commands_bar[-1:], size - n, axis=0)])

    def compile(self, batch: int, n_steps: int):
        """Compiles for commands [batch, n_steps, 3]; returns the compiled executable."""
        self._announce(batch, n_steps)
        spec = jax.ShapeDtypeStruct((batch, n_steps, 3), jnp.float32, sharding=self.batch_sharding)
        return self.fn.lower(self.mjx_model, self.rest, spec).compile()

    def run_device(self, commands: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Runs sharded commands [B, T, 3] (B padded); returns device arrays, not waited on.
        The first call of a shape announces its compile on stderr (process 0 only)."""
        self._announce(*commands.shape[:2])
        return self.fn(self.mjx_model, self.rest, commands)

    def _announce(self, batch: int, n_steps: int) -> None:
        """The stderr line before the first compile of a shape (`mjx_arm.compile_notice`), on
        process 0 only."""
        if jax.process_index() == 0:
            compile_notice.announce_compile(
                (id(self.fn), (batch, n_steps, 3)),
                batch,
                n_steps,
                what=f"the sharded MJX rollout over {self.n_devices} device(s)",
            )

    def __call__(self, commands_bar: np.ndarray, size: int | None = None):
        n = commands_bar.shape[0]
        poses, ok = self.run_device(self.shard(self.pad(commands_bar, size)))
        return _gather(poses)[:n].astype(np.float32), _gather(ok)[:n]


def _replicate(tree, sharding: NamedSharding):
    """Puts a pytree of arrays, the same on every process, on every device of `sharding`.

    Each process copies its host values to its own devices only: `jax.device_put` of a committed
    single-device array to another process's devices needs cross-host transfers (which the CPU
    backend of jax 0.10.2 refuses), and of a host array compares every leaf across processes
    (one collective per leaf, and float64 model fields then differ from their float32 copies).
    """

    def put(x):
        x = np.asarray(x, jax.dtypes.canonicalize_dtype(np.asarray(x).dtype))
        return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])

    return jax.tree.map(put, jax.device_get(tree))


def _local_mjx_model(arm: arm_lib.Arm) -> mjx.Model:
    """`arm.mjx_model`, but on this process's own device in a multi-process run.

    `mjx.put_model` puts a model on ``jax.devices()[0]``, which on every process but 0 is another
    process's device, so its arrays cannot be read there. The two-process test
    (tests/test_multiprocess.py) checks that this copy gives the same data as `arm.mjx_model`.
    """
    if jax.process_count() == 1:
        return arm.mjx_model
    m = copy.copy(arm.mj_model)
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_SENSOR  # as `Arm.mjx_model`
    return mjx.put_model(m, device=jax.local_devices()[0])


@functools.lru_cache(maxsize=16)
def _sharded_fn(devices, tip_site, actuators, n_substeps, valve_params, controls):
    """jit(vmap(rollout)) of (mjx_model, (rest_qpos, rest_qvel), commands [B, T, 3]), cached."""
    mesh = batch_mesh(devices)
    replicated, batch = NamedSharding(mesh, P()), NamedSharding(mesh, P("batch"))

    def rollout(mjx_model, rest, commands_bar):
        return arm_lib.rollout_program(
            mjx_model,
            commands_bar,
            tip_site=tip_site,
            actuators=actuators,
            n_substeps=n_substeps,
            valve_params=valve_params,
            controls=controls,
            rest_qpos=rest[0],
            rest_qvel=rest[1],
        )

    return jax.jit(
        jax.vmap(rollout, in_axes=(None, None, 0)),
        in_shardings=(replicated, replicated, batch),
        out_shardings=batch,
    )


def _gather(x: jax.Array) -> np.ndarray:
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return np.asarray(multihost_utils.process_allgather(x, tiled=True))
    return np.asarray(x)


def simulate(
    arm: arm_lib.Arm,
    programs_bar: np.ndarray,
    *,
    backend: str = "auto",
    chunk: int = 4096,
    progress: Callable[[int], None] | None = None,
    sharded: ShardedRollout | None = None,
    fixed_size: bool = False,
) -> np.ndarray:
    """Simulates babbling programs in chunks.

    Args:
      arm: the arm in its domain.
      programs_bar: [N, T, 3] commands (bar).
      backend: "mjx", "c" or "auto" (see `resolve_backend`).
      chunk: programs per call; with mjx every chunk is padded to the same size (one compile);
        with c at most C_MAX_CHUNK.
      progress: called with the number of trajectories finished after each chunk.
      sharded: a `ShardedRollout` of `arm` to reuse (mjx only); built when None.
      fixed_size: mjx only: pad every call to `chunk` (rounded up to the device count) even when
        N < chunk, so runs of different N share one compilation.

    Returns:
      [N, T, 6] float32 poses: tip position (m) then unit d3.

    Raises:
      SimulationDivergedError: a trajectory diverged.
    """
    backend = resolve_backend(backend)
    n = programs_bar.shape[0]
    poses = np.zeros(programs_bar.shape[:2] + (arm_lib.POSE_DIM,), np.float32)
    if backend == "mjx":
        sharded = sharded if sharded is not None else ShardedRollout(arm)
        size = padded_size(chunk if fixed_size else min(chunk, n), sharded.n_devices)
    else:
        size = min(chunk, C_MAX_CHUNK)
    for start in range(0, n, size):
        stop = min(start + size, n)
        if backend == "mjx":
            out, ok = sharded(programs_bar[start:stop], size)
            _raise_if_diverged(ok, offset=start)
            poses[start:stop] = out
        else:
            poses[start:stop] = arm.rollout(programs_bar[start:stop], backend="c")
        if progress is not None:
            progress(stop - start)
    return poses


def _raise_if_diverged(ok: np.ndarray, offset: int = 0) -> None:
    """ok: [B, T] flags of trajectories offset .. offset + B."""
    bad = np.flatnonzero(~ok[:, -1])
    if bad.size:
        first = np.array([np.argmin(ok[b]) for b in bad])
        raise arm_lib.SimulationDivergedError(
            f"simulation diverged in {bad.size} trajectory(ies) {(bad + offset)[:10].tolist()},"
            f" first at control step(s) {first[:10].tolist()}",
            bad + offset,
            first,
        )


# ---------------------------------------------------------------------------------- datasets


def babble(
    config: BabbleConfig = PAPER,
    *,
    model_path: str | Path | None = None,
    xml: str | None = None,
    progress: bool = True,
) -> list[dataset.Dataset]:
    """Generates the babbling datasets of every domain and split in `config`.

    Args:
      config: babbling options; backend "rod" simulates in `mjx_arm.load_rod(domain)`.
      model_path, xml: the MJCF (default: the committed model), as for `mjx_arm.load`; with
        backend "rod" neither may be given (the rod is made from the arm's physical values,
        not from an MJCF).
      progress: show a tqdm bar (trajectories).

    Returns:
      One `Dataset` per (domain, split), in order, all with the same task-space bounds (min/max
      over every returned dataset's poses).

    Raises:
      NotEnoughMemoryError: the run would not fit the available memory (`check_memory`).
      ValueError: backend "rod" with an MJCF (`model_path` or `xml`).
    """
    from tqdm.auto import tqdm

    if config.backend == "rod" and (model_path is not None or xml is not None):
        raise ValueError(
            "backend 'rod' simulates the reference rod, which is made from the arm's physical"
            " values, not from an MJCF: give no model_path or xml"
        )
    check_memory(config)  # before any work: a run that cannot fit fails now, not after hours
    splits = config.splits()
    total = len(config.domains) * sum(splits.values())
    results = []
    backend = resolve_backend(config.backend)
    # One batch size for every split and domain: one compilation for the whole run.
    chunk = min(config.chunk, max(splits.values()))
    with tqdm(
        total=total,
        unit="traj",
        disable=not progress or jax.process_index() != 0,
        desc=f"babbling ({backend})",
    ) as bar:
        for domain in config.domains:
            name = domains.resolve(domain).name
            if backend == "rod":
                arm = _load_rod(domain)
            else:
                arm = arm_lib.load(model_path, domain, xml=xml)
            sharded = ShardedRollout(arm) if backend == "mjx" else None
            for split, n in splits.items():
                bar.set_postfix_str(f"{name}/{split}")
                programs = family_programs(config, n, name, split)
                _check_processes_agree(config, backend, arm, programs)
                if backend == "rod":
                    poses = rod_babble.simulate_rod(
                        arm, programs, chunk=config.chunk, progress=bar.update
                    ).astype(np.float32)
                    results.append(_dataset(config, backend, arm, split, programs, poses))
                    continue
                poses = simulate(
                    arm,
                    programs,
                    backend=backend,
                    chunk=chunk,
                    progress=bar.update,
                    sharded=sharded,
                    fixed_size=True,
                )
                results.append(_dataset(config, backend, arm, split, programs, poses))
    low, high = dataset.workspace_bounds(*(d.poses for d in results))
    return [d.with_bounds(low, high) for d in results]


def _load_rod(domain: str):
    """The reference rod in `domain`, in babbling's dtype (imported here: `mjx_arm.rod_arm`
    imports the model generator, which chain runs do not need)."""
    from mjx_arm.rod_arm import load_rod

    return load_rod(domain, dtype=rod_babble.DTYPE)


def _dataset(config: BabbleConfig, backend: str, arm, split: str, programs, poses):
    """One (domain, split) dataset of a run; its bounds are set later, over the whole run."""
    return dataset.Dataset(
        pressures_bar=programs,
        poses=poses,
        pose_low=np.zeros(6, np.float32),
        pose_high=np.ones(6, np.float32),
        domain=arm.domain.name,
        domain_fields=dataclasses.asdict(arm.domain),
        model_hash=arm.model_hash,
        seed=config.seed,
        split=split,
        config=_config_dict(config, backend),
    )


def _check_processes_agree(
    config: BabbleConfig, backend: str, arm: arm_lib.Arm, programs: np.ndarray
) -> None:
    """In a multi-process run, raises RuntimeError (on every process) unless all processes have
    the same options, model and programs: each fills only its own shards of the batch, so a
    process started with, say, another --seed would silently mix two runs' data."""
    if jax.process_count() == 1:
        return
    from jax.experimental import multihost_utils

    text = json.dumps(_config_dict(config, backend), sort_keys=True) + arm.model_hash
    digest = zlib.crc32(programs.tobytes(), zlib.crc32(text.encode())) & 0x7FFFFFFF
    digests = multihost_utils.process_allgather(np.array([digest], np.int32), tiled=True)
    if len(set(digests.tolist())) > 1:
        raise RuntimeError(
            f"the {jax.process_count()} processes disagree on the babbling options, model or"
            f" programs (digests by process: {digests.tolist()}); start every process with the"
            " same command line and MJCF"
        )


def _config_dict(config: BabbleConfig, backend: str) -> dict:
    d = dataclasses.asdict(config)
    d["domains"] = list(d["domains"])
    d["backend"] = backend
    if backend == "rod":  # only there: the chain's files stay byte for byte as before
        d |= rod_babble.rod_config_fields()
    return d


def dataset_path(out_dir: str | Path, domain: str, split: str) -> Path:
    """Where `run` writes a (domain, split) dataset."""
    return Path(out_dir) / f"{domain}_{split}.npz"


def run(
    config: BabbleConfig,
    out_dir: str | Path,
    *,
    model_path: str | Path | None = None,
    xml: str | None = None,
    progress: bool = True,
) -> list[Path]:
    """Generates the datasets of `config` and writes them, as one folder with a manifest, to
    ``out_dir/<domain>_<split>.npz`` (`dataset.save_folder`).

    `out_dir` is checked before any simulation (`dataset.check_output_folder`); an earlier run's
    folder there is replaced only once the new one is complete.

    Returns:
      The paths written (none on processes other than 0 of a multi-host run).

    Raises:
      FileExistsError, PermissionError: `out_dir` cannot hold a run (checked first).
    """
    dataset.check_output_folder(out_dir)
    datasets = babble(config, model_path=model_path, xml=xml, progress=progress)
    if jax.process_index() != 0:
        return []
    named = {dataset_path(out_dir, d.domain, d.split).name: d for d in datasets}
    return dataset.save_folder(out_dir, named)
