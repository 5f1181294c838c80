"""All service configuration in one place, read from ``VGN_*`` environment variables."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from service.grip import GripConfig
from vgn_contract.gripper_description import DEFAULT_GRIPPER
from vgn_contract.schemas import SWITCH_EFFECTS

#: The packaged default model; the service uses it when ``VGN_MODEL`` is unset.
PACKAGED_MODEL = Path(__file__).parent / "models" / "vgn.safetensors"
#: The packaged network for volumes fused from one frame; the default of ``VGN_ONE_VIEW_MODEL``.
PACKAGED_ONE_VIEW_MODEL = Path(__file__).parent / "models" / "vgn-one-view.safetensors"
#: The packaged networks of single hands, ``<hand name>.safetensors`` with its card beside it: the
#: defaults of ``VGN_HAND_MODELS``.
PACKAGED_HAND_MODELS = Path(__file__).parent / "models" / "grippers"
#: ``VGN_MODEL=none``: serve without a model (the antipodal planner still works).
NO_MODEL = "none"


def _switch_default(name: str) -> str:
    """The operator's default for an on/off grasp option, worded from what the option does."""
    return (
        f"the default of requests that leave {name} unset (a request may still ask for {name}=true or "
        f"{name}=false): {SWITCH_EFFECTS[name]}"
    )


class Settings(BaseSettings):
    """Service settings; every field can be set as ``VGN_<FIELD>`` (e.g. ``VGN_MODEL``)."""

    model_config = SettingsConfigDict(env_prefix="VGN_", extra="ignore")

    model: Literal["none"] | Path | None = Field(
        default=None,
        description="weights file (.safetensors preferred, or a .pt/.pth state_dict); "
        "when unset the packaged default is used; 'none' serves without a model (antipodal planner only)",
    )
    one_view_model: Literal["none"] | Path | None = Field(
        default=None,
        description="weights of the network that answers VGN requests on volumes fused from one frame (one "
        "fixed camera), in place of VGN_MODEL's, for sessions of the default hand; its card beside it gives "
        "its operating threshold. Unset: the packaged one-view weights where they ship, else none; 'none': "
        "VGN_MODEL's network answers every volume. Not loaded without VGN_MODEL's network",
    )
    device: Literal["auto", "cpu", "cuda"] = Field(default="auto", description="torch device")
    torch_threads: int | None = Field(
        default=None, ge=1, description="torch intra-op threads; unset: half the usable cores, 1 to 8"
    )
    inference: Literal["fast", "reference"] = Field(
        default="fast",
        description="'fast': the network folded for inference, the same grasps for less arithmetic "
        "(see Design); 'reference': VGN as trained, float32",
    )
    heads: Literal["auto", "on-demand", "whole"] = Field(
        default="auto",
        description="where the fast form computes grasp rotation and width: 'on-demand' at the voxels "
        "detection reads (on the CPU), 'whole' at every voxel with quality; auto: on demand on a CPU, "
        "whole on a GPU",
    )
    precision: Literal["auto", "fp32", "bf16"] = Field(
        default="auto", description="of the fast form; auto: bf16 on CPUs with native bf16, else fp32"
    )
    batch_window_ms: float | None = Field(
        default=None,
        ge=0,
        le=1000,
        description="how long a grasp request waits for others to share its forward pass, in milliseconds; "
        "unset: 2 on a GPU, 0 on a CPU",
    )
    max_batch: int = Field(default=32, ge=1, le=256, description="most grids in one forward pass")
    lanes: int | None = Field(
        default=None,
        ge=1,
        le=64,
        description="threads that share the grids of one forward pass on a CPU (turned grids, concurrent "
        "requests), each with the torch threads; unset: the usable cores over the torch threads",
    )
    reuse_output: bool = Field(
        default=True,
        description="answer a grasp request on a session whose volume has not changed since the last one "
        "from that one's network output (detection only)",
    )
    turn_average: bool = Field(default=True, description=_switch_default("turn_average"))
    clearance: bool = Field(default=True, description=_switch_default("clearance"))
    grip: bool = Field(default=True, description=_switch_default("grip"))
    alternatives: bool = Field(
        default=True,
        description="when a check drops a grasp, try it again turned about its approach, tilted and stepped "
        "back (service/checks.py) and keep the pose whose fingers both grip at the square grip "
        "(VGN_GRIP_PREFERRED_ALIGNMENT) most squarely, so that a location the network is confident about "
        "is not lost to its one orientation; only where the grip check runs",
    )
    fallback_threshold: float = Field(
        default=0.5,
        ge=0.0,
        le=1.0,
        description="when a VGN request that names no threshold finds no grasp that passes the checks at "
        "the model's operating threshold, answer with the grasps that pass them down to this quality "
        "(the answer's threshold says which applied; the surface's antipodal pairs come first, "
        "VGN_SURFACE_FALLBACK), so that a robot is not left with nothing to do while objects remain; 1 "
        "answers with none",
    )
    surface_fallback: bool = Field(
        default=True,
        description="when a VGN request that names no threshold finds no grasp that passes the checks at the "
        "model's operating threshold, answer first with the antipodal pairs of the observed surface that "
        "pass the clearance check (the answer's model says 'antipodal'; their own antipodal test on the fine "
        "cloud stands in for the grip check), and only where there are none with the network's grasps down "
        "to VGN_FALLBACK_THRESHOLD: the network's few confident locations on a shape it does not know can "
        "all fail a check while the surface still offers a grip",
    )
    narrow_pair_share: float = Field(
        default=0.75,
        gt=0.0,
        le=1.0,
        description="when the surface's antipodal pairs answer (the antipodal check's or the fallback's), "
        "only those that close on at most this share of the hand's opening, where some do: a pair that "
        "spans most of the opening slips several times as often in simulation (docs/concepts.md)",
    )
    antipodal_check: bool = Field(
        default=True,
        description="where the grip check runs, keep only the checked VGN grasps whose fingers close "
        "on opposed faces of the network's grid (its surface, normals from the TSDF gradient, within "
        "VGN_ANTIPODAL_CHECK_GRID_ANGLE of the closing axis); where none does, the surface's antipodal pairs "
        "that pass every check and close on the grid's opposed faces too (the answer's model says "
        "'antipodal'); where there are none, the VGN grasps that close on opposed faces of the fine cloud "
        "(within VGN_ANTIPODAL_CHECK_ANGLE), then the other checked pairs, then the checked grasps as they "
        "were: a grasp whose pads meet slanted or one-sided faces slips more often than one that meets "
        "opposed faces (docs/concepts.md)",
    )
    antipodal_check_grid_angle: float = Field(
        default=35.0,
        gt=0.0,
        lt=90.0,
        description="degrees: how far the mean normal of the grid's faces under each pad may turn from the "
        "closing axis for VGN_ANTIPODAL_CHECK to count them as opposed without reading the fine cloud",
    )
    antipodal_check_angle: float = Field(
        default=20.0,
        gt=0.0,
        lt=90.0,
        description="degrees: how far the mean normal of the fine cloud's faces under each pad may turn from "
        "the closing axis for VGN_ANTIPODAL_CHECK to count them as opposed",
    )
    grip_preferred_alignment: float = Field(
        default=GripConfig().preferred_alignment,
        ge=-1.0,
        le=1.0,
        description="the grip check's square grip, as the cosine between the surface normal and the closing "
        "fingers: where some of a request's grasps grip that squarely, only those are kept (one grasp per "
        "look is executed, and beside a square grip the others slip more often); 0.5 or less keeps every grasp "
        "that passes the check, for clients that choose among many by reachability",
    )
    grippers: list[Path] = Field(
        default_factory=list,
        description="gripper description files (JSON, docs/your-gripper.md) the service knows besides the "
        "built-in hands, as a JSON list: VGN_GRIPPERS='[\"/etc/vgn/my-hand.json\"]'",
    )
    network_grippers: list[str] = Field(
        default_factory=lambda: [DEFAULT_GRIPPER],
        description="the hands the loaded network plans for, as a JSON list; a session for any other hand is "
        "refused. The packaged network was trained for 'franka' only. A hand with its own network "
        "(VGN_HAND_MODELS) gets that one instead",
    )
    hand_models: dict[str, Literal["none"] | Path] = Field(
        default_factory=dict,
        description="each hand's own network, as a JSON object from a hand name (built in or in VGN_GRIPPERS) "
        "to weights with their card beside them, or to 'none': "
        'VGN_HAND_MODELS=\'{"robotiq-2f85": "/models/robotiq.safetensors"}\'. It answers every session of '
        "that hand, in place of VGN_MODEL's network and the one-view network, at its card's operating "
        "threshold; a card that records another hand version than the hand's stops the start-up. A hand "
        f"left out gets the packaged {PACKAGED_HAND_MODELS.relative_to(Path(__file__).parent.parent)}/"
        "<name>.safetensors where it ships; 'none': no network of its own (VGN_NETWORK_GRIPPERS says whether "
        "VGN_MODEL's serves it). Not loaded without VGN_MODEL's network",
    )
    max_sessions: int = Field(default=64, ge=1)
    session_ttl_s: float = Field(default=1800.0, gt=0, description="idle seconds before a session expires")
    max_frame_bytes: int = Field(
        default=32 * 1024 * 1024,
        ge=1024,
        description="largest depth image in a frame upload, in bytes (413 beyond); a request body may be "
        "64 KiB larger, for the frame's meta JSON and multipart headers",
    )
    api_key: str | None = Field(default=None, description="when set, required as X-API-Key or Bearer token")
    grpc_port: int = Field(
        default=50051,
        ge=0,
        le=65535,
        description="port of the gRPC front end, started with the app; 0 turns it off",
    )
    grpc_host: str = Field(default="127.0.0.1", description="address the gRPC front end listens on")
    cloud_resolution: int = Field(
        default=120, ge=16, le=400, description="voxels a side of the fine volume behind /cloud"
    )
    depth_scale_registration: bool = Field(
        default=True,
        description="scale each depth frame about its camera so that its points meet the surface the session's "
        "volume already holds before fusing it: a sensor whose distance error drifts from frame to frame "
        "(a few per cent) otherwise fuses smeared, doubled surfaces (docs/concepts.md)",
    )
    cloud_max_pending_frames: int = Field(
        default=512,
        ge=1,
        le=4096,
        description="frames a session queues for the cloud volume (float16: 0.6 MB for 640x480); fused in "
        "the background when uploads pause or by the next cloud read; a full queue makes the next upload "
        "wait for room, none is dropped",
    )
    cloud_max_queued_mb: float = Field(
        default=512.0,
        gt=0,
        description="frames queued for cloud volumes, all sessions together, in MiB; beyond it an upload "
        "to a session with frames queued waits for room",
    )

    @field_validator("model", "one_view_model", "api_key", mode="before")
    @classmethod
    def _empty_is_unset(cls, value: object) -> object:
        """``VGN_API_KEY=`` or ``VGN_MODEL=`` in an env file means "not set"."""
        return _weights_setting(value)

    @field_validator("hand_models", mode="before")
    @classmethod
    def _hand_none(cls, value: object) -> object:
        """Each hand's entry read as ``VGN_MODEL`` is (an empty one: unset)."""
        if not isinstance(value, dict):
            return value
        chosen = {hand: _weights_setting(path) for hand, path in value.items()}
        return {hand: path for hand, path in chosen.items() if path is not None}

    def model_path(self) -> Path | None:
        """The weights to load: ``VGN_MODEL``, else the packaged default if it exists; ``None``
        for ``VGN_MODEL=none``."""
        return _weights_path(self.model, PACKAGED_MODEL)

    def one_view_model_path(self) -> Path | None:
        """The one-view weights to load, chosen as :meth:`model_path` chooses; ``None`` also
        without a main network, since the one-view network only stands in for it."""
        if self.model_path() is None:
            return None
        return _weights_path(self.one_view_model, PACKAGED_ONE_VIEW_MODEL)

    def hand_model_paths(self, hands: Iterable[str]) -> dict[str, Path]:
        """The weights of each of ``hands`` (the names the service knows) that has a network of its
        own, chosen as :meth:`model_path` chooses, the packaged one being
        ``PACKAGED_HAND_MODELS/<name>.safetensors``; none without a main network, as for the
        one-view network. An entry for a name not in ``hands`` is the caller's to refuse."""
        if self.model_path() is None:
            return {}
        chosen = {
            name: _weights_path(self.hand_models.get(name), PACKAGED_HAND_MODELS / f"{name}.safetensors")
            for name in sorted(hands)
        }
        return {name: path for name, path in chosen.items() if path is not None}


def _weights_setting(value: object) -> object:
    """A weights (or key) setting as given: empty is unset (``None``), ``none`` in any case is ``NO_MODEL``."""
    if value == "":
        return None
    if isinstance(value, str) and value.strip().lower() == NO_MODEL:
        return NO_MODEL
    return value


def _weights_path(setting: Path | str | None, packaged: Path) -> Path | None:
    """A weights setting's file: the path it names, ``None`` for ``none``, and when unset the
    packaged file if it ships."""
    if setting == NO_MODEL:
        return None
    if setting is not None:
        return Path(setting)
    return packaged if packaged.exists() else None
