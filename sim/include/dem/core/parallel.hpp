// The calling thread's place in the current OpenMP team (0 of 1 outside a parallel region or
// without OpenMP).
#pragma once
#ifdef _OPENMP
#include <omp.h>
#endif

namespace dem {

struct ThreadRank {
  int index = 0;   ///< 0 .. count-1
  int count = 1;
};

inline ThreadRank this_thread_rank() {
#ifdef _OPENMP
  return {omp_get_thread_num(), omp_get_num_threads()};
#else
  return {};
#endif
}

}  // namespace dem
