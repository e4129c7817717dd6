"""A Ray cluster address checked before any work: the standard library only, so the commands'
argument checks stay cheap (ray and torch load later, when the work starts)."""
import socket

from cyclist_formats.errors import UserError

PROBE_TIMEOUT_S = 3.0  # a cluster's GCS answers a TCP connect in milliseconds; ray.init waits minutes


def check_address(address, flag="--address"):
    """A Ray cluster address: 'auto' (the one `ray start` left on this machine) or HOST:PORT
    (ray://HOST:PORT too) where something accepts a TCP connection within PROBE_TIMEOUT_S, so a
    wrong address fails in seconds with one line instead of ray.init retrying for minutes."""
    if address is None or address == "auto":
        return address
    hostport = address[len("ray://"):] if address.startswith("ray://") else address
    host, sep, port = hostport.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UserError(f"{flag} {address!r}: expected 'auto' or HOST:PORT (e.g. 10.0.0.5:6379)")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=PROBE_TIMEOUT_S):
            pass
    except OSError as e:
        why = f"no answer within {PROBE_TIMEOUT_S:.0f} s" if isinstance(e, socket.timeout) else (e.strerror or str(e))
        raise UserError(f"{flag} {address}: no Ray cluster answers there ({why}); "
                        "start one with `ray start --head` or check the address") from None
    return address
