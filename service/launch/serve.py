"""``vgn-client serve``: the service in this process under uvicorn, or a fleet of replicas behind
HAProxy (``--replicas N``). ``vgn-client`` parses the options and hands them here by name, so
the client package never imports the server; this module imports uvicorn only when it runs.
"""

from __future__ import annotations

import argparse
import errno
import os
import signal
import sys

from client.extras import missing_extra
from service.launch.embedded import bind_error
from service.launch.fleet import Fleet, FleetConfig, FleetError


def run(args: argparse.Namespace) -> int:
    """Serve until stopped. Exit status: 0 stopped, 1 a port is taken or the fleet failed, 2 the
    service extra is missing."""
    try:
        import uvicorn
    except ImportError:
        print(f"error: {missing_extra('serving', 'service')}", file=sys.stderr)
        return 2
    if args.replicas is not None:
        return _serve_fleet(args)
    if args.model:
        os.environ["VGN_MODEL"] = args.model
    if args.grpc_port is not None:
        os.environ["VGN_GRPC_PORT"] = str(args.grpc_port)
    os.environ.setdefault("VGN_GRPC_HOST", args.host)
    grpc_port = os.environ.get("VGN_GRPC_PORT") or "50051"  # the service checks the value
    grpc_host = os.environ["VGN_GRPC_HOST"]
    listeners = [("port", args.host, args.port, "--port")]
    if grpc_port.isdigit() and grpc_port != "0":
        listeners.append(
            ("gRPC port", grpc_host, int(grpc_port), "--grpc-port, or --grpc-port 0 for no gRPC")
        )
    for problem in filter(None, (_listen_problem(*listener) for listener in listeners)):
        print(f"error: {problem}", file=sys.stderr)
        return 1
    grpc = f"gRPC on grpc://{grpc_host}:{grpc_port}" if grpc_port != "0" else "gRPC off"
    print(f"serving HTTP on http://{args.host}:{args.port}, {grpc}", file=sys.stderr)
    uvicorn.run("service.app:app", host=args.host, port=args.port)
    return 0


def _serve_fleet(args: argparse.Namespace) -> int:
    """``serve --replicas N``: the fleet runs until Ctrl-C or SIGTERM, then stops as a whole."""
    grpc_port = 50051 if args.grpc_port is None else args.grpc_port
    config = FleetConfig(args.replicas, args.host, args.port, grpc_port or None, args.model)
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(0))  # unwinds through stop() below
    fleet = None
    try:
        fleet = Fleet(config)
        print(f"starting {args.replicas} replicas and HAProxy ...", file=sys.stderr)
        fleet.start()
        grpc = f", gRPC on {fleet.grpc_url}" if fleet.grpc_url else ", gRPC off"
        print(
            f"serving HTTP on {fleet.url}{grpc} through HAProxy, {args.replicas} replicas:", file=sys.stderr
        )
        for replica in fleet.replicas:
            print(f"  {replica.url}  {replica.grpc_url}  (pid {replica.pid})", file=sys.stderr)
        fleet.watch()
    except FleetError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        pass
    finally:
        if fleet is not None:
            fleet.stop()
    return 0


def _listen_problem(name: str, host: str, port: int, option: str) -> str | None:
    """Why the service could not listen on ``host:port``, checked before it starts: otherwise
    it loads the model first and then fails with a traceback from deep inside its start-up."""
    error = bind_error(host, port)
    if error is None:
        return None
    if error.errno == errno.EADDRINUSE:
        return f"{name} {port} is in use on {host} (another vgn-client serve?): pick another with {option}"
    return f"cannot listen on {host}:{port} ({error.strerror or error})"
