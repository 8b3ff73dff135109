"""Type stubs of the tsah package (the names of tsah.__all__; the extension tsah._tsah holds them).

python/tests/test_stubs.py compares these names with the module's own, so the two cannot drift.
"""
import os
from typing import Any, Callable, Iterator, Sequence, Union, overload

import numpy as np
import numpy.typing as npt

__version__: str
cuda_built: bool

_PathLike = Union[str, os.PathLike[str]]
_Integer = Union[int, np.integer[Any]]
_Number = Union[float, int, np.floating[Any], np.integer[Any]]
_ArrayLike = npt.ArrayLike
_ProgressCallback = Callable[[dict[str, Any]], object]


class Error(RuntimeError):
    """An error of the toolkit, with its one-line message ('FILE: problem'). The base of ConfigError,
    DataError (FileError) and Failure; a RuntimeError."""


class ConfigError(Error, ValueError):
    """An invalid request: an option or argument out of range, an unknown name, settings that
    contradict each other, a call the object cannot serve (a tsah.Error and a ValueError)."""


class DataError(Error, ValueError):
    """Unusable data: NaN coordinates, a tree that is not a tree, a tree built for another animation,
    bytes that are not a tree file (a tsah.Error and a ValueError)."""


class FileError(DataError):
    """An input or tree file that cannot be read; the message starts with the file name (a
    tsah.DataError)."""


class Failure(Error):
    """The request and the data were fine but the work failed: a write error, a full disk, not
    enough memory, a GPU error (a tsah.Error, so a RuntimeError)."""


class ArgumentTypeError(ConfigError, TypeError):
    """An argument of the wrong type or dtype (a tsah.ConfigError and a TypeError)."""


class Animation:
    """An animated triangle mesh: one triangle list for all frames, vertex positions per keyframe
    and the keyframe times; positions between keyframes are interpolated linearly (clamped)."""

    def __init__(self, triangles: _ArrayLike, positions: _ArrayLike, times: _ArrayLike | None = None,
                 name: str = "") -> None:
        """triangles: integers (T, 3); positions: floats (F, V, 3) or (V, 3) for one frame; times:
        strictly increasing (F,) (default 0 .. F-1). Arrays, lists or tuples."""
    @property
    def name(self) -> str:
        """Name of the input (file stem) or the given name."""
    @property
    def triangle_count(self) -> int:
        """_Number of triangles."""
    @property
    def vertex_count(self) -> int:
        """_Number of vertices."""
    @property
    def keyframe_count(self) -> int:
        """_Number of keyframes."""
    @property
    def start_time(self) -> float:
        """Time of the first keyframe."""
    @property
    def end_time(self) -> float:
        """Time of the last keyframe."""
    @property
    def triangles(self) -> npt.NDArray[np.uint32]:
        """Vertex indices, uint32 array (T, 3) (a copy)."""
    @property
    def positions(self) -> npt.NDArray[np.float32]:
        """Keyframe positions, float32 array (F, V, 3) (a copy)."""
    @property
    def times(self) -> npt.NDArray[np.float64]:
        """Keyframe times, float64 array (F,)."""
    @property
    def bounds(self) -> npt.NDArray[np.float32]:
        """Bounds over every keyframe: float32 array (2, 3), minimum then maximum."""
    def positions_at(self, t: _Number) -> npt.NDArray[np.float32]:
        """Vertex positions at time t, float32 array (V, 3) (linear between keyframes, clamped)."""
    def uniform_times(self, n: _Integer) -> npt.NDArray[np.float64]:
        """n times spread uniformly over [start_time, end_time], both ends included."""
    def resample(self, n: _Integer) -> Animation:
        """A new animation with n keyframes at uniform_times(n) (`tsah resample --frames n`)."""
    def segment(self, t0: _Number, t1: _Number) -> Animation:
        """The part between t0 and t1: keyframes at t0, t1 and every original keyframe between them."""
    def save(self, path: _PathLike) -> None:
        """Writes the animation as a .tanim file (atomically), as `tsah resample` does."""


class Tree:
    """One BVH over the triangles of an animation, with node boxes for each representative frame
    and the header of its .tbvh file. Made by optimize, read_tree or TreeSet[i]; pickled as its
    .tbvh bytes."""

    @property
    def node_count(self) -> int:
        """Nodes of the tree (interior and leaves)."""
    @property
    def leaf_count(self) -> int:
        """Leaves of the tree."""
    @property
    def depth(self) -> int:
        """Depth of the deepest leaf (the root: 0)."""
    @property
    def triangle_count(self) -> int:
        """Triangles in the tree."""
    @property
    def frame_count(self) -> int:
        """Box sets stored per node (the representative frames)."""
    @property
    def info(self) -> dict[str, Any]:
        """The .tbvh header as a dict (the keys of `tsah info --json`)."""
    @property
    def optimization(self) -> dict[str, Any] | None:
        """For a T-SAH tree built in this process: the optimizer's costs and batch history; None otherwise."""
    @property
    def triangle_order(self) -> npt.NDArray[np.uint32]:
        """Triangle id of each slot of the .tbvh triangle array (leaves own consecutive slots)."""
    def frame_costs(self, ct: _Number = 3.0, ci: _Number = 2.0) -> npt.NDArray[np.float64]:
        """Eq. 1 cost at each stored (representative) frame."""
    def costs(self, animation: Animation, eval_frames: _Integer = 50, ct: _Number | None = None,
              ci: _Number | None = None, threads: _Integer = 0) -> npt.NDArray[np.float64]:
        """Eq. 1 cost of the tree refitted to eval_frames frames uniform over the animation."""
    def save(self, path: _PathLike) -> None:
        """Writes the tree as a .tbvh file (atomically), byte for byte what `tsah optimize` writes."""
    def to_bytes(self) -> bytes:
        """The .tbvh file's bytes."""


class TreeSet:
    """K trees over one animation, each built for one part of its time range; tree_at(t) picks the
    tree of a time. Made by optimize(..., segments=...) or read_tree of a set file; pickled as its
    .tbvh bytes."""

    def __len__(self) -> int:
        """The number of trees."""
    def __getitem__(self, index: _Integer) -> Tree:
        """Tree `index` (negative indices count from the end)."""
    def __iter__(self) -> Iterator[Tree]:
        """The trees in time order."""
    @property
    def ranges(self) -> list[tuple[float, float]]:
        """Each tree's build range (start, end) in seconds, in order."""
    @property
    def switch_times(self) -> list[float]:
        """The times where tree i hands over to tree i + 1 (the middle of their overlap)."""
    def tree_at(self, t: _Number) -> int:
        """The index of the tree used at time t."""
    @property
    def triangle_count(self) -> int:
        """Triangles in every tree."""
    @property
    def info(self) -> dict[str, Any]:
        """The set's header: segmentation, overlap, budget, budget_relative, trees."""
    @property
    def segmentation(self) -> dict[str, Any] | None:
        """For a set built in this process: the search's record (parts, costs, ...); None otherwise."""
    def costs(self, animation: Animation, eval_frames: _Integer = 50, ct: _Number = 3.0, ci: _Number = 2.0,
              threads: _Integer = 0) -> npt.NDArray[np.float64]:
        """Eq. 1 cost at eval_frames uniform times, each with the tree of its time refitted to it."""
    def save(self, path: _PathLike) -> None:
        """Writes the set as one .tbvh file (atomically), what `tsah optimize --segments` writes."""
    def to_bytes(self) -> bytes:
        """The .tbvh set file's bytes."""


class CpuRuntime:
    """A tree refitted to a frame of the animation it was built for, traced on the CPU."""

    def __init__(self, tree: Tree | TreeSet, animation: Animation, threads: _Integer = 0, layout: str = "auto",
                 triangles: str = "woop") -> None:
        """layout: 'auto' (the widest SIMD layout of this processor), 'bvh2', 'bvh4' or 'bvh8'; triangles:
        'woop' or 'vertices', how bvh4 / bvh8 hold each frame's triangles (bvh2: 'woop' only). A TreeSet:
        refit(time) refits and traces the tree of the time's part (tree_index)."""
    def refit(self, time: _Number | _ArrayLike) -> None:
        """Refits to the animation at this time (interpolated, clamped), or to vertex positions, a float array (V, 3)."""
    def refit_positions(self, positions: _ArrayLike) -> None:
        """Refits to given vertex positions, a float array (V, 3)."""
    def trace(self, origins: _ArrayLike, directions: _ArrayLike, tmin: _ArrayLike = 0.0,
              tmax: _ArrayLike = float("inf"), out: Any = None) -> np.recarray[Any, Any]:
        """Closest hits: a record array (N,) with t, u, v and triangle (-1 and t = inf for a miss)."""
    def occluded(self, origins: _ArrayLike, directions: _ArrayLike, tmin: _ArrayLike = 0.0,
                 tmax: _ArrayLike = float("inf"), out: Any = None) -> npt.NDArray[np.bool_]:
        """True for each ray that hits anything within (tmin, tmax)."""
    def closest_points(self, points: _ArrayLike, radius: _ArrayLike = float("inf")) -> np.recarray[Any, Any]:
        """For each point (N, 3), the closest point on the current frame's triangles within radius: a record
        array (N,) with distance (inf when none), triangle (-1 then), u, v and point."""
    def overlapping_triangles(self, lo: _ArrayLike,
                              hi: _ArrayLike) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
        """For each box (lo, hi: (N, 3)), the triangles whose current box overlaps it: (offsets, ids)."""
    @property
    def bounds(self) -> npt.NDArray[np.float32]:
        """Bounds of the current frame, float32 (2, 3)."""
    @property
    def layout(self) -> str:
        """The layout traced: bvh2, bvh4 or bvh8."""
    @property
    def triangles(self) -> str:
        """How the traced tree holds the frame's triangles: woop or vertices."""
    @property
    def tree_index(self) -> int:
        """The index of the tree traced in a tree set (chosen by the last refit(time)); 0 for a tree."""
    @property
    def last_ray_pass(self) -> dict[str, Any]:
        """The last trace/occluded: rays and the wall time (ms) of the C++ batch call alone."""


class DeviceArray:
    """C-contiguous memory on a CUDA device owned by the module (only when cuda_built): a GPU
    runtime's results for device rays, or an out= array. Exported without a copy through
    __cuda_array_interface__ (version 3) and DLPack (torch.from_dlpack, cupy.asarray)."""

    def __init__(self, shape: Sequence[_Integer], typestr: str = "<f4", device: _Integer = 0) -> None:
        """An uninitialised array; typestr: '<f4', '<i4', '<u4', '|b1' or '|u1'."""
    @property
    def shape(self) -> tuple[int, ...]:
        """The shape, a tuple."""
    @property
    def typestr(self) -> str:
        """numpy's typestr of the elements, e.g. '<f4'."""
    @property
    def device(self) -> int:
        """The CUDA device the memory is on."""
    @property
    def __cuda_array_interface__(self) -> dict[str, Any]:
        """The CUDA array interface, version 3 (strides None; stream: the one its contents follow)."""
    def __dlpack__(self, *, stream: int | None = None, max_version: tuple[int, int] | None = None,
                   dl_device: tuple[int, int] | None = None, copy: bool | None = None) -> Any:
        """A DLPack capsule of the array (no copy) after `stream` waits for its contents: DLPack 1.0's
        "dltensor_versioned" (version 1.0) when max_version's major is 1 or more, else "dltensor"."""
    def __dlpack_device__(self) -> tuple[int, int]:
        """(2, device): kDLCUDA and the device."""


_DeviceHits = dict[str, DeviceArray]  # t, u, v (float32), triangle (int32) and, two-level, instance (int32)
_Stream = Any  # None, an int cudaStream_t, or an object with __cuda_stream__ or cuda_stream


class GpuRuntime:
    """The same as CpuRuntime on a CUDA device (only when cuda_built). Also takes CUDA device arrays
    (__cuda_array_interface__ or DLPack: torch, CuPy) in place, on the caller's stream."""

    def __init__(self, tree: Tree | TreeSet, animation: Animation, device: _Integer = 0, layout: str = "auto") -> None:
        """device: the CUDA device index; layout: 'auto' (the binary layout), 'bvh2' or 'cwbvh'. Raises
        tsah.Failure when no device is usable. A TreeSet: as CpuRuntime."""
    def refit(self, time: _Number | _ArrayLike | Any, *, stream: _Stream = None, wait: bool = True) -> None:
        """Refits on the device to the animation at this time, or to vertex positions (V, 3): host
        arrays, or a float32 device array used in place (checked on the device; wait=False: the
        DataError of a refused frame is raised by the next refit or check())."""
    def refit_positions(self, positions: _ArrayLike | Any, *, stream: _Stream = None, wait: bool = True) -> None:
        """Refits to given vertex positions (V, 3)."""
    def check(self) -> None:
        """Raises the DataError of the last refit(device positions, wait=False) if it refused its frame."""
    def trace(self, origins: _ArrayLike | Any, directions: _ArrayLike | Any, tmin: _ArrayLike | Any = 0.0,
              tmax: _ArrayLike | Any = float("inf"), out: Any = None, *,
              stream: _Stream = None) -> np.recarray[Any, Any] | _DeviceHits:
        """Closest hits, as CpuRuntime.trace; for device rays a dict of device arrays t, u, v, triangle
        (or out=, a dict of any of them), not waited for."""
    def occluded(self, origins: _ArrayLike | Any, directions: _ArrayLike | Any, tmin: _ArrayLike | Any = 0.0,
                 tmax: _ArrayLike | Any = float("inf"), out: Any = None, *,
                 stream: _Stream = None) -> npt.NDArray[np.bool_] | DeviceArray:
        """True for each ray that hits anything within (tmin, tmax); a bool device array for device rays."""
    def closest_points(self, points: _ArrayLike, radius: _ArrayLike = float("inf")) -> np.recarray[Any, Any]:
        """For each point (N, 3), the closest point on the current frame's triangles within radius: a record
        array (N,) with distance (inf when none), triangle (-1 then), u, v and point."""
    def overlapping_triangles(self, lo: _ArrayLike,
                              hi: _ArrayLike) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int32]]:
        """For each box (lo, hi: (N, 3)), the triangles whose current box overlaps it: (offsets, ids)."""
    @property
    def device_name(self) -> str:
        """The name of the CUDA device."""
    @property
    def layout(self) -> str:
        """The layout traced: bvh2 or cwbvh."""
    @property
    def tree_index(self) -> int:
        """The index of the tree traced in a tree set (chosen by the last refit(time)); 0 for a tree."""
    @property
    def last_ray_pass(self) -> dict[str, Any]:
        """The last host-array trace/occluded: rays and the traversal kernel's device time (ms)."""
    @property
    def last_update(self) -> dict[str, float]:
        """Device time (ms) of the last refit from a time or host positions: interpolate_ms, refit_ms,
        woop_ms, total_ms."""


class TwoLevelScene:
    """A scene file kept as two levels: one tree (BLAS) per distinct source, one T-SAH tree (TLAS)
    over the instances (tsah.build_two_level, tsah.load_two_level)."""

    def save(self, path: _PathLike) -> None:
        """Writes the two-level .tbvh file (version 3), what `tsah optimize SCENE` writes."""
    def baked_triangles(self, instances: _ArrayLike, triangles: _ArrayLike) -> npt.NDArray[np.int32]:
        """Per (instance, triangle of its source) pair, the triangle's id in tsah.load(scene_path)."""
    @property
    def instance_count(self) -> int:
        """Number of instances (a flattened object's triangles are one instance)."""
    @property
    def blas_count(self) -> int:
        """Number of bottom-level trees: one per distinct source."""
    @property
    def flattened_objects(self) -> list[str]:
        """Names of the scene file's objects flattened into one source."""
    @property
    def start_time(self) -> float:
        """Time of the scene's first frame."""
    @property
    def end_time(self) -> float:
        """Time of the scene's last frame."""
    @property
    def frame_times(self) -> npt.NDArray[np.float64]:
        """The scene's frame times, float64 array."""
    @property
    def info(self) -> dict[str, Any]:
        """The structure as `tsah info TREE SCENE --json` describes it (and auto's structure_choice)."""


class TwoLevelRuntime:
    """A two-level scene traced on the CPU (BLAS refits per pose, instance transforms, TLAS refit)."""

    def __init__(self, scene: TwoLevelScene, threads: _Integer = 0, layout: str = "auto",
                 tlas: str = "refit", pose_triangles: str = "vertices") -> None:
        """layout: the BLAS layout ('auto', 'bvh2', 'bvh4', 'bvh8'); tlas: 'refit' or 'rebuild';
        pose_triangles: 'vertices' or 'woop', how bvh4 / bvh8 poses hold their triangles."""
    def update(self, time: _Number) -> None:
        """The scene at this time; ends a blurred frame."""
    def update_shutter(self, open: _Number, close: _Number) -> None:
        """A blurred frame over the shutter [open, close]: rays then take their times (times=)."""
    def trace(self, origins: _ArrayLike, directions: _ArrayLike, tmin: _ArrayLike = 0.0,
              tmax: _ArrayLike = float("inf"), times: _ArrayLike | None = None,
              out: Any = None) -> np.recarray[Any, Any]:
        """Closest hits: a record array with t, u, v, instance and triangle (-1 and t = inf for a miss);
        times: each ray's shutter fraction in a blurred frame."""
    def occluded(self, origins: _ArrayLike, directions: _ArrayLike, tmin: _ArrayLike = 0.0,
                 tmax: _ArrayLike = float("inf"), times: _ArrayLike | None = None,
                 out: Any = None) -> npt.NDArray[np.bool_]:
        """True for each ray that hits anything within (tmin, tmax)."""
    @property
    def time(self) -> float:
        """The scene time of the last update (of a blurred frame: its close)."""
    @property
    def blurred(self) -> bool:
        """True after an update_shutter that made a blurred frame (until update)."""
    @property
    def instance_boxes(self) -> npt.NDArray[np.float32]:
        """The instances' world boxes at the current time, float32 (I, 2, 3)."""
    @property
    def memory_bytes(self) -> int:
        """Bytes the runtime holds (trees, triangles, positions, instances)."""


class GpuTwoLevelRuntime:
    """A two-level scene traced on a CUDA device from host rays or device arrays in place (only when
    cuda_built)."""

    def __init__(self, scene: TwoLevelScene, device: _Integer = 0, layout: str = "auto", tlas: str = "refit") -> None:
        """layout: the BLAS layout, 'auto' (bvh2), 'bvh2' or 'cwbvh'; tlas: 'refit', 'lbvh' or 'hlbvh-sah'.
        Raises tsah.Failure when no device is usable."""
    def update(self, time: _Number) -> None:
        """The scene at this time, on the device; ends a blurred frame."""
    def update_shutter(self, open: _Number, close: _Number) -> None:
        """A blurred frame over the shutter [open, close] on the device: rays then take their times (times=)."""
    def trace(self, origins: _ArrayLike | Any, directions: _ArrayLike | Any, tmin: _ArrayLike | Any = 0.0,
              tmax: _ArrayLike | Any = float("inf"), times: _ArrayLike | Any | None = None,
              out: Any = None, *, stream: _Stream = None) -> np.recarray[Any, Any] | _DeviceHits:
        """Closest hits, as TwoLevelRuntime.trace; times: each ray's shutter fraction in a blurred frame.
        For device rays a dict of device arrays t, u, v, instance, triangle (or out=, a dict of any of
        them), not waited for."""
    def occluded(self, origins: _ArrayLike | Any, directions: _ArrayLike | Any, tmin: _ArrayLike | Any = 0.0,
                 tmax: _ArrayLike | Any = float("inf"), times: _ArrayLike | Any | None = None,
                 out: Any = None, *, stream: _Stream = None) -> npt.NDArray[np.bool_] | DeviceArray:
        """True for each ray that hits anything within (tmin, tmax); a bool device array for device rays."""
    @property
    def time(self) -> float:
        """The scene time of the last update (of a blurred frame: its close)."""
    @property
    def blurred(self) -> bool:
        """True after an update_shutter that made a blurred frame (until update)."""
    @property
    def device_name(self) -> str:
        """The name of the CUDA device."""
    @property
    def last_update(self) -> dict[str, Any]:
        """Device time (ms) of the last update: upload_ms, blas_ms, tlas_ms, tlas_rebuild_ms, total_ms;
        blas_refits, instances, tlas_nodes."""


def cuda_available() -> bool:
    """True when the CUDA runtime was built and a GPU is present."""


def load(path: _PathLike, fps: _Number = 0.0, clip: str = "") -> Animation:
    """Loads any input the command line reads (.tanim, .aff, animated models, mesh files and
    sequences, JSON manifests); importer warnings become UserWarnings. Ctrl-C is raised when the
    load returns."""


def generate(kind: str, triangles: _Integer = 4000, frames: _Integer = 30, seed: _Integer = 1) -> Animation:
    """A procedural animation ('explode', 'wave' or 'swap'), as `tsah generate` makes it."""


@overload
def optimize(animation: Animation, method: str = "tsah", k: _Integer = 0, frames: _Integer = 5,
             selection: str = "mh", seed: _Integer = 1, ct: _Number = 3.0, ci: _Number = 2.0,
             max_leaf: _Integer = 8, time_limit: _Number = 0.0, min_improvement: _Number = 1e-05,
             threads: _Integer = 0, optimizer: str = "sequential", segments: None = None,
             budget: _Number | None = None, budget_cost: _Number | None = None, overlap: _Number | None = None,
             eval_frames: _Integer | None = None, reference_frames: _Integer | None = None,
             max_trees: _Integer | None = None, reproducible: bool = False,
             progress: _ProgressCallback | None = None) -> Tree:
    """One Tree for the whole animation, exactly as `tsah optimize` builds it (same options and
    defaults). optimizer: 'sequential', 'parallel' or 'gpu'. progress(event) is called on this
    thread with a dict ('message'; for optimizer batches 'batch', 'cost', 'average', 'elapsed_s',
    'steps'); an exception in it cancels the call. Ctrl-C stops the call (KeyboardInterrupt)."""
@overload
def optimize(animation: Animation, method: str = "tsah", k: _Integer = 0, frames: _Integer = 5,
             selection: str = "mh", seed: _Integer = 1, ct: _Number = 3.0, ci: _Number = 2.0,
             max_leaf: _Integer = 8, time_limit: _Number = 0.0, min_improvement: _Number = 1e-05,
             threads: _Integer = 0, optimizer: str = "sequential", *, segments: _Integer | str,
             budget: _Number | None = None, budget_cost: _Number | None = None, overlap: _Number | None = None,
             eval_frames: _Integer | None = None, reference_frames: _Integer | None = None,
             max_trees: _Integer | None = None, reproducible: bool = False,
             progress: _ProgressCallback | None = None) -> TreeSet:
    """With segments (K trees, or 'auto': the fewest trees within budget / budget_cost) a TreeSet,
    exactly as `tsah optimize --segments` builds it (reproducible: build times 0, the same bytes)."""


def evaluate(animation: Animation, methods: str | Sequence[str] = "sah0,sahstar,tsah0,tsah2,tsah4,rebuild",
             frames: _Integer = 5, eval_frames: _Integer = 50, max_leaf: _Integer = 8, ct: _Number = 3.0,
             ci: _Number = 2.0, selection: str = "mh", seed: _Integer = 1, time_limit: _Number = 0.0,
             min_improvement: _Number = 1e-05, threads: _Integer = 0, optimizer: str = "sequential",
             progress: _ProgressCallback | None = None) -> dict[str, Any]:
    """The paper's Table 1 for one animation, as `tsah evaluate --json` computes it."""


def read_tree(path: _PathLike) -> Tree | TreeSet:
    """Reads and validates a .tbvh file: a Tree for a file of one tree, a TreeSet for a set file."""


def tree_from_bytes(data: bytes | bytearray | memoryview, name: str = "<bytes>") -> Tree | TreeSet:
    """A Tree or a TreeSet from the bytes of a .tbvh file; tsah.DataError when they are not one."""


def load_two_level(tree_path: _PathLike, scene_path: _PathLike) -> TwoLevelScene:
    """Reads a two-level .tbvh file (version 3) with the scene file it was built for (checked)."""


def build_two_level(scene_path: _PathLike, structure: str = "auto", k: _Integer = 0, frames: _Integer = 5,
                    selection: str = "mh", seed: _Integer = 1, ct: _Number = 3.0, ci: _Number = 2.0,
                    max_leaf: _Integer = 8, time_limit: _Number = 0.0, min_improvement: _Number = 1e-05,
                    threads: _Integer = 0, optimizer: str = "sequential",
                    tlas_trees: str | _Integer = "auto", tlas_budget: _Number = 1.1,
                    progress: _ProgressCallback | None = None) -> TwoLevelScene:
    """The two-level structure of a scene file, as `tsah optimize SCENE --structure auto|two-level`."""
