"""Inference runtimes beside the service's own: is any of them faster with the same grasps?

    python -m benchmarks.inference_backends [--model PATH] [--threads T] [--repeats N]
                                            [--skip-compile] [--json PATH]

Times one forward pass over a 40³ grid (the recorded cluttered scenes of
``tests/data/recorded_grids.npz``, in turn), every form once per round (interleaved):

1. the naive float32 eager network as trained (the reference);
2. the service's fast form (``service.vgn.fast``) in float32, and in bfloat16 on CPUs with
   native bf16 (the service's default there);
3. ``torch.compile`` of the fast form (the first call, which compiles, is timed apart);
4. with the ``runtimes`` extra (``pip install -e '.[runtimes]'``): ONNX Runtime on the CPU, and
   OpenVINO on the CPU at f32 and bf16 inference precision, both running the fast form's
   function exported to ONNX (the folded convolutions; exported unfolded, both runtimes took
   longer than torch's naive eager pass here).

Each form is checked as the service's acceptance test checks its own: on every recorded scene,
the top-10 grasps at threshold 0.3 agree with the reference's (within a voxel, 5° and 0.02 of
quality, neighbouring near-ties excused), and the largest difference of any output is printed.

Why: the network is most of a grasp request's cost, and a runtime that computed the same
grasps faster would be worth an optional backend. All forms run with the threads the service
would choose (``--threads`` to change it) and share the machine with nothing else.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from benchmarks.timing import Measurement, Operation, run_interleaved
from service.planner import native_bf16
from service.runtime import configured_threads
from service.settings import PACKAGED_MODEL
from service.vgn.agreement import Tolerance, disagreements, network_outputs, voxelwise_disagreements
from service.vgn.checkpoint import load_vgn
from service.vgn.detection import DetectionConfig, detect_grasps
from service.vgn.fast import HEAD_CHANNELS, NORM_EPS, FastVGN, pixel_shuffle_3d
from tests.helpers.grids import recorded_grids

VOXEL = 0.3 / 40
THRESHOLD = 0.3
TOLERANCE = Tolerance(position_m=VOXEL, angle_deg=5.0, quality=0.02)
REFERENCE = "torch eager float32 (reference)"

#: A forward pass: (N, N, N) float32 grid → quality (N³), rotation (4, N³), width (N³).
Forward = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]


class ExportableFastVGN(nn.Module):
    """The fast form's function in operations an ONNX export can trace: its forward writes
    into a preallocated tensor and activates in place, which tracing does not follow."""

    def __init__(self, fast: FastVGN) -> None:
        super().__init__()
        self.fast = fast

    def forward(self, grid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Quality, rotation and width, as :meth:`FastVGN.forward` returns them."""
        heads = pixel_shuffle_3d(self.fast.head_logits(grid))
        quality, rotation, width = heads.split(HEAD_CHANNELS, dim=1)
        return torch.sigmoid(quality), F.normalize(rotation, dim=1, eps=NORM_EPS), width


@dataclass
class Form:
    """One way of running the network, and what it measured."""

    name: str
    forward: Forward
    note: str = ""
    timing: Measurement | None = None
    max_output_difference: float = float("nan")
    disagreements: list[str] | None = None

    def as_dict(self) -> dict[str, Any]:
        """The form's figures for the JSON file: its timing row and its agreement."""
        timing = self.timing.as_dict() if self.timing else {"name": self.name, "note": self.note}
        return {
            **timing,
            "max_output_difference": self.max_output_difference,
            "disagreements": self.disagreements,
        }


def torch_forward(network: nn.Module) -> Forward:
    """A forward pass of a torch module, as numpy arrays."""
    return lambda grid: network_outputs(network, grid)


def precision_name(dtype: torch.dtype) -> str:
    """How the table names a compute precision."""
    return "bfloat16" if dtype == torch.bfloat16 else "float32"


def array_forward(run: Callable[[np.ndarray], list[np.ndarray]]) -> Forward:
    """A forward pass of a runtime that takes and returns (1, C, N, N, N) arrays."""

    def forward(grid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        quality, rotation, width = run(np.ascontiguousarray(grid[None, None]))
        return quality[0, 0], rotation[0], width[0, 0]

    return forward


def export_onnx(fast: FastVGN, path: Path, resolution: int = 40) -> None:
    """The fast form's function as an ONNX file (TorchScript-based exporter, opset 17)."""
    example = torch.zeros(1, 1, resolution, resolution, resolution)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the exporter's deprecation notices
        torch.onnx.export(
            ExportableFastVGN(fast).eval(),
            (example,),
            str(path),
            input_names=["grid"],
            output_names=["quality", "rotation", "width"],
            opset_version=17,
            dynamo=False,
        )


def torch_forms(reference: nn.Module, compile_too: bool) -> tuple[list[Form], list[str]]:
    """The reference, the fast form in each precision the CPU runs natively, and their compiled
    twins; and what could not be built."""
    dtypes = [torch.float32] + ([torch.bfloat16] if native_bf16(torch.device("cpu")) else [])
    forms = [Form(REFERENCE, torch_forward(reference), "baseline")]
    for dtype in dtypes:
        forms.append(
            Form(
                f"torch fast form {precision_name(dtype)}", torch_forward(FastVGN.from_vgn(reference, dtype))
            )
        )
    skipped = []
    for dtype in dtypes if compile_too else []:
        label = precision_name(dtype)
        forward = torch_forward(torch.compile(FastVGN.from_vgn(reference, dtype), dynamic=False))
        started = time.perf_counter()
        try:
            forward(np.zeros((40, 40, 40), dtype=np.float32))
        except Exception as error:  # no C++ compiler, or an inductor that cannot take the model
            skipped.append(f"torch.compile {label}: {str(error).splitlines()[0]}")
            continue
        note = f"first call (compiling) {time.perf_counter() - started:.1f} s"
        forms.append(Form(f"torch.compile fast form {label}", forward, note))
    return forms, skipped


def runtime_forms(reference: nn.Module, threads: int, directory: Path) -> tuple[list[Form], list[str]]:
    """ONNX Runtime and OpenVINO on the exported fast form, where installed; and what was skipped."""
    forms: list[Form] = []
    skipped: list[str] = []
    path = directory / "vgn-fast.onnx"
    try:
        export_onnx(FastVGN.from_vgn(reference), path)
    except Exception as error:  # onnx missing, or an exporter that cannot take the model
        return [], [f"ONNX export failed, no runtime rows: {error}"]
    try:
        import onnxruntime as ort
    except ImportError:
        skipped.append("ONNX Runtime (pip install onnxruntime)")
    else:
        options = ort.SessionOptions()
        options.intra_op_num_threads, options.inter_op_num_threads = threads, 1
        session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        name = session.get_inputs()[0].name
        forms.append(
            Form(
                f"ONNX Runtime {ort.__version__} float32",
                array_forward(lambda g: session.run(None, {name: g})),
            )
        )
    try:
        import openvino as ov
    except ImportError:
        skipped.append("OpenVINO (pip install openvino)")
    else:
        core = ov.Core()
        model = core.read_model(str(path))
        capabilities = core.get_property("CPU", "OPTIMIZATION_CAPABILITIES")
        for precision in ["f32"] + (["bf16"] if "BF16" in capabilities else []):
            config = {"INFERENCE_NUM_THREADS": threads, "INFERENCE_PRECISION_HINT": precision,
                      "PERFORMANCE_HINT": "LATENCY"}  # fmt: skip
            request = core.compile_model(model, "CPU", config).create_infer_request()
            outputs = request.model_outputs
            run = (lambda r, o: lambda g: [r.infer({0: g})[output] for output in o])(request, outputs)
            forms.append(Form(f"OpenVINO {ov.__version__.split('-')[0]} {precision}", array_forward(run)))
    return forms, skipped


def check_agreement(forms: list[Form], grids: list[tuple[str, np.ndarray]]) -> None:
    """Fill in each form's largest output difference from the reference (the first form) and what
    the acceptance check finds: top-10 grasps, neighbouring near-ties excused where the outputs
    agree voxel by voxel at the graspable voxels."""
    config = DetectionConfig(threshold=THRESHOLD)

    def grasps(grid: np.ndarray, outputs: tuple[np.ndarray, np.ndarray, np.ndarray]) -> list:
        return detect_grasps(grid, *outputs, VOXEL, np.eye(4), config)

    reference = {name: forms[0].forward(grid) for name, grid in grids}
    for form in forms:
        form.disagreements, largest = [], 0.0
        for name, grid in grids:
            outputs, expected = form.forward(grid), reference[name]
            for want, got in zip(expected, outputs, strict=True):
                largest = max(largest, float(np.abs(np.asarray(got, np.float32) - want).max()))
            found = disagreements(
                grasps(grid, expected), grasps(grid, outputs), TOLERANCE, neighbour_swaps=True
            )
            found += voxelwise_disagreements(expected, outputs, expected[0] >= 0.5, TOLERANCE)
            form.disagreements += [f"{name}: {reason}" for reason in found]
        form.max_output_difference = largest


def time_interleaved(
    forms: list[Form], grids: list[tuple[str, np.ndarray]], repeats: int, warmup: int
) -> None:
    """Time every form once per round (``benchmarks.timing``'s interleaved schedule), on the grids in turn."""

    def on_grid(form: Form) -> Callable[[int], object]:
        return lambda i: form.forward(grids[i % len(grids)][1])

    operations = [Operation(form.name, "forward", on_grid(form), form.note) for form in forms]
    for form, timing in zip(forms, run_interleaved(operations, repeats, warmup), strict=True):
        form.timing = timing


def format_table(forms: list[Form]) -> str:
    """The forms as a text table, with speed-ups over the reference (the first form)."""
    width = max(len(form.name) for form in forms) + 2
    reference = forms[0].timing.p50
    header = f"{'form':<{width}}{'p50 ms':>9}{'p95 ms':>9}{'x ref':>8}{'max |diff|':>12}  top-10 grasps  note"
    lines = [header, "-" * (len(header) + 8)]
    for form in forms:
        timing = form.timing
        verdict = "agree" if not form.disagreements else f"{len(form.disagreements)} disagreement(s)"
        lines.append(
            f"{form.name:<{width}}{timing.p50:>9.2f}{timing.p95:>9.2f}{reference / timing.p50:>8.1f}"
            f"{form.max_output_difference:>12.2e}  {verdict:<13}  {form.note}"
        )
    return "\n".join(lines)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", type=Path, default=PACKAGED_MODEL, help="VGN weights (.safetensors)")
    parser.add_argument("--threads", type=int, default=None, help="threads (default: the service's choice)")
    parser.add_argument("--repeats", type=int, default=40)
    parser.add_argument("--warmup", type=int, default=5)
    parser.add_argument("--skip-compile", action="store_true", help="leave out torch.compile (slow to start)")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Build, check and time every form; print the table and write the JSON file if asked."""
    args = parse_args(argv)
    threads = args.threads or configured_threads()
    torch.set_num_threads(threads)
    reference = load_vgn(args.model)
    grids = recorded_grids()
    forms, skipped = torch_forms(reference, not args.skip_compile)
    with tempfile.TemporaryDirectory(prefix="vgn-runtimes-") as directory:
        extra, not_installed = runtime_forms(reference, threads, Path(directory))
    forms, skipped = forms + extra, skipped + not_installed
    check_agreement(forms, grids)
    time_interleaved(forms, grids, args.repeats, args.warmup)
    print(f"VGN forward pass on one 40³ grid, {threads} thread(s), {args.repeats} interleaved rounds "
          f"over {len(grids)} recorded scenes; torch {torch.__version__}")  # fmt: skip
    print(format_table(forms))
    for line in skipped:
        print(f"left out: {line}")
    for form in forms:
        for reason in form.disagreements or []:
            print(f"{form.name}: {reason}")
    if args.json is not None:
        args.json.write_text(json.dumps({"threads": threads, "forms": [f.as_dict() for f in forms],
                                         "skipped": skipped}, indent=1))  # fmt: skip
        print(f"results written to {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
