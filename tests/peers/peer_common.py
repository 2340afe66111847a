"""What the MAVLink peer flights share: a free UDP port, one-line failures, and the
`sim` binary started for a flight and stopped with SIGTERM as systemd would."""

import contextlib
import os
import signal
import socket
import subprocess
import sys


def free_port(kind=socket.SOCK_DGRAM):
    """A free local UDP port (TCP with `kind=socket.SOCK_STREAM`), bound and released."""
    s = socket.socket(socket.AF_INET, kind)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def fail(peer, msg):
    """One line saying what went wrong, then exit 1."""
    print(f"{peer} peer: FAILED: {msg}", flush=True)
    sys.exit(1)


@contextlib.contextmanager
def running_sim(sim_path, listen_port, remote_port):
    """The simulator flying indoor-static, listening on `listen_port` and sending to
    `remote_port` before a peer has spoken; stopped with SIGTERM when done."""
    env = dict(os.environ, LANDING_LOG="warn", LANDING_IPC_PREFIX=f"peer_{os.getpid()}_")
    sim = subprocess.Popen(
        [sim_path, "--scenario", "indoor-static", "--duration-s", "120",
         "--mavlink-listen", f"127.0.0.1:{listen_port}",
         "--mavlink-remote", f"127.0.0.1:{remote_port}"],
        env=env)
    try:
        yield sim
    finally:
        sim.send_signal(signal.SIGTERM)
        try:
            sim.wait(timeout=10)
        except subprocess.TimeoutExpired:
            sim.kill()
