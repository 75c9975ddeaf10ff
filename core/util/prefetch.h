#ifndef NUPMPC_CORE_UTIL_PREFETCH_H_
#define NUPMPC_CORE_UTIL_PREFETCH_H_

// Software prefetch for the horizon sweeps. A sweep over a long horizon reads or writes a
// stored vector per row or step (the filter's v = V c; the input filter's W, ξ and input
// records) and does a short chain of dependent arithmetic with it (a dot product that
// needs the previous row's update), so the core cannot run far enough ahead to issue the
// next rows' memory accesses itself, and once the stored vectors no longer fit in the
// caches the hardware prefetchers alone leave most of the memory latency exposed. Asking
// for the data of a row kPrefetchRows (a step kPrefetchSteps) ahead hides it
// (`nupmpc-bench --scaling` measures the long-horizon sweeps).

namespace nupmpc::core {

// How many rows ahead a sweep asks for the stored vector it will read.
inline constexpr int kPrefetchRows = 16;
// How many time steps ahead a sweep asks for what it will store for a step.
inline constexpr int kPrefetchSteps = 2;

// Starts loading the cache lines of data[0, count) for reading. A hint only: it never
// faults and changes no value.
inline void PrefetchForRead(const double* data, int count) {
  constexpr int kDoublesPerLine = 64 / static_cast<int>(sizeof(double));
  for (int i = 0; i < count; i += kDoublesPerLine) __builtin_prefetch(data + i, /*rw=*/0, /*locality=*/3);
  if (count > 0) __builtin_prefetch(data + count - 1, 0, 3);  // the last line when data is not line-aligned
}

// The same for lines a sweep is about to write: fetched for ownership ahead, so that its
// stores do not each wait for their line to be requested.
inline void PrefetchForWrite(double* data, int count) {
  constexpr int kDoublesPerLine = 64 / static_cast<int>(sizeof(double));
  for (int i = 0; i < count; i += kDoublesPerLine) __builtin_prefetch(data + i, /*rw=*/1, /*locality=*/3);
  if (count > 0) __builtin_prefetch(data + count - 1, 1, 3);
}

}  // namespace nupmpc::core

#endif  // NUPMPC_CORE_UTIL_PREFETCH_H_
