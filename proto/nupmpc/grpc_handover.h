#ifndef NUPMPC_PROTO_NUPMPC_GRPC_HANDOVER_H_
#define NUPMPC_PROTO_NUPMPC_GRPC_HANDOVER_H_

// gRPC runs a reactor's reactions (OnReadDone, OnWriteDone, OnCancel, OnDone) on its own
// threads, each after the operation that asked for it (StartRead, StartWrite, Finish) and
// after the handler (or the client, with StartCall) handed the reactor over. Both ends of
// nupmpc.v1 use these: the server's reactors and the client library's Control call. libgrpc orders them with its own
// synchronisation, which Debian's build does not expose to ThreadSanitizer: unannotated, TSan
// reports every hand-over of a reactor's fields from one gRPC thread to the next as a race.
// These two calls state gRPC's ordering for TSan; they compile to nothing in other builds.

#if defined(__SANITIZE_THREAD__)
#define NUPMPC_THREAD_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define NUPMPC_THREAD_SANITIZER 1
#endif
#endif

#if defined(NUPMPC_THREAD_SANITIZER)
extern "C" void __tsan_acquire(void* addr);
extern "C" void __tsan_release(void* addr);
#endif

namespace nupmpc {

// Before handing `reactor` to gRPC and before each operation started on it.
inline void HandToGrpc([[maybe_unused]] const void* reactor) {
#if defined(NUPMPC_THREAD_SANITIZER)
  __tsan_release(const_cast<void*>(reactor));
#endif
}

// First thing in each reaction of `reactor`.
inline void TakeFromGrpc([[maybe_unused]] const void* reactor) {
#if defined(NUPMPC_THREAD_SANITIZER)
  __tsan_acquire(const_cast<void*>(reactor));
#endif
}

}  // namespace nupmpc

#endif  // NUPMPC_PROTO_NUPMPC_GRPC_HANDOVER_H_
