"""Channel credentials for a server with TLS, mTLS or bearer tokens (the server's
--tls_* and --auth_tokens_file flags); the rules of the C++ client
(client/channel_security.cc): a token rides on every call as `authorization: Bearer TOKEN`,
and without TLS it is sent only to a loopback or Unix-socket target (gRPC's local
credentials), never in clear text across a network."""

from __future__ import annotations

from typing import Union

import grpc

# A channel argument: (name, value).
ChannelOption = tuple[str, Union[int, str]]

_LOCAL_PREFIXES = ("localhost:", "127.", "[::1]:", "ipv4:127.", "ipv6:[::1]:", "dns:///localhost:")


def is_local_target(target: str) -> bool:
    return target.startswith(("unix:", "unix-abstract:")) or target.startswith(_LOCAL_PREFIXES)


def _read(option: str, path: str) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as error:
        raise ValueError(f"{option} {path}: cannot be read ({error.strerror})") from None


# grpc ships no type stubs, so its classes are Any to the type checker.
class _BearerToken(grpc.AuthMetadataPlugin):  # type: ignore[misc]
    def __init__(self, token: str) -> None:
        self._metadata = (("authorization", f"Bearer {token}"),)

    def __call__(self, context: grpc.AuthMetadataContext, callback: grpc.AuthMetadataPluginCallback) -> None:
        callback(self._metadata, None)


def channel_credentials(target: str, tls: bool = False, ca_file: str | None = None, cert_file: str | None = None,
                        key_file: str | None = None, token: str | None = None) -> grpc.ChannelCredentials | None:
    """grpc.ChannelCredentials for `target`, or None for a plaintext channel. Errors
    (ValueError) name the option: unreadable files, a token without TLS to a remote target."""
    uses_tls = tls or ca_file or cert_file
    if uses_tls:
        if bool(cert_file) != bool(key_file):
            raise ValueError("cert_file and key_file: give both or neither")
        channel = grpc.ssl_channel_credentials(
            root_certificates=_read("ca_file", ca_file) if ca_file else None,
            private_key=_read("key_file", key_file) if key_file else None,
            certificate_chain=_read("cert_file", cert_file) if cert_file else None)
    elif token:
        if not is_local_target(target):
            raise ValueError(f"token: sent only over TLS to a remote server ({target}); give tls=True (or ca_file)")
        unix = target.startswith("unix")
        channel = grpc.local_channel_credentials(grpc.LocalConnectionType.UDS if unix else
                                                 grpc.LocalConnectionType.LOCAL_TCP)
    else:
        return None
    if not token:
        return channel
    return grpc.composite_channel_credentials(channel, grpc.metadata_call_credentials(_BearerToken(token)))


# The clients' keepalive (the C++ client's are the same: client/client.cc).
KEEPALIVE_TIME_MS = 2000
KEEPALIVE_TIMEOUT_MS = 2000


def channel_options(server_name: str | None = None, own_subchannel: bool = False) -> list[ChannelOption]:
    # Plans of long horizons exceed gRPC's 4 MB default; the server enforces its own limit.
    options: list[ChannelOption] = [("grpc.max_receive_message_length", -1), ("grpc.max_send_message_length", -1)]
    # HTTP/2 keepalive: a ping every KEEPALIVE_TIME_MS, also without calls in flight, and a
    # connection whose ping is not answered within KEEPALIVE_TIMEOUT_MS is closed, so a
    # partition or a frozen server is found in seconds, not by TCP's timers (minutes). The
    # server accepts pings this often (nupmpc-server's keepalive enforcement policy).
    options += [("grpc.keepalive_time_ms", KEEPALIVE_TIME_MS), ("grpc.keepalive_timeout_ms", KEEPALIVE_TIMEOUT_MS),
                ("grpc.keepalive_permit_without_calls", 1), ("grpc.http2.max_pings_without_data", 0)]
    if server_name:
        options.append(("grpc.ssl_target_name_override", server_name))
    if own_subchannel:
        # A connection of this channel's own, not shared (with its reconnect back-off)
        # through gRPC's global subchannel pool with other channels to the same address.
        options.append(("grpc.use_local_subchannel_pool", 1))
    return options
