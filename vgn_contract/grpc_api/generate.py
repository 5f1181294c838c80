"""Generate the Python stubs from the ``.proto``: ``python -m vgn_contract.grpc_api.generate [DIR]``.

Needs ``grpcio-tools`` (the ``dev`` extra). protoc names the modules after the proto's path
(``vgn/v1/...``) and imports them absolutely; the stubs live in this package instead, so the
import in the service stub is made relative.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
#: The ``.proto`` ships in this package too, so the stubs can be regenerated from an install.
PROTO_ROOT = PACKAGE_DIR.parent / "proto"
PROTO = Path("vgn/v1/grasp_planning.proto")
STUBS = ("grasp_planning_pb2.py", "grasp_planning_pb2.pyi", "grasp_planning_pb2_grpc.py")
ABSOLUTE_IMPORT = "from vgn.v1 import grasp_planning_pb2"
RELATIVE_IMPORT = "from . import grasp_planning_pb2"


def generate(out_dir: Path = PACKAGE_DIR, proto_root: Path = PROTO_ROOT) -> list[Path]:
    """Write the stubs of ``proto_root/vgn/v1/grasp_planning.proto`` into ``out_dir``."""
    from grpc_tools import protoc

    with tempfile.TemporaryDirectory() as scratch:
        arguments = [
            "grpc_tools.protoc",
            f"-I{proto_root}",
            f"--python_out={scratch}",
            f"--pyi_out={scratch}",
            f"--grpc_python_out={scratch}",
            str(proto_root / PROTO),
        ]
        if protoc.main(arguments) != 0:
            raise RuntimeError(f"protoc failed on {proto_root / PROTO}")
        written = []
        for name in STUBS:
            text = (Path(scratch) / PROTO.parent / name).read_text()
            target = Path(out_dir) / name
            target.write_text(text.replace(ABSOLUTE_IMPORT, RELATIVE_IMPORT))
            written.append(target)
    return written


def main() -> None:
    """Regenerate the stubs into the directory given (default: this package) and list what was written."""
    out_dir = Path(sys.argv[1]) if len(sys.argv) > 1 else PACKAGE_DIR
    for path in generate(out_dir):
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
