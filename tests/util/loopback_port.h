#ifndef NUPMPC_TESTS_UTIL_LOOPBACK_PORT_H_
#define NUPMPC_TESTS_UTIL_LOOPBACK_PORT_H_

namespace nupmpc::testing {

// A loopback port that binds now, for a server process a test starts (and restarts) on it;
// 0 if none was found. Drawn at random from below the kernel's ephemeral range (or above
// it where nothing is below), not bound to port 0: the kernel picks the source port of
// every outgoing connection from that range, so a port it handed out could be taken by a
// connection of a test running beside this one before the server binds it, or while the
// server is down for a restart. tests/util/loopback_port.py does the same for the Python
// tests and scripts.
int FreeLoopbackPort();

}  // namespace nupmpc::testing

#endif  // NUPMPC_TESTS_UTIL_LOOPBACK_PORT_H_
