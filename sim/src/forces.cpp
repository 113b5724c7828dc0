#include "dem/forces.hpp"

#include <algorithm>
#include <cmath>
#ifdef _OPENMP
#include <omp.h>
#endif

namespace dem {

namespace {

// One pair: adds the contact force to f[i] (and minus it to f[j]) if the spheres overlap.
template <class Law>
inline void pair_force(const Law& law, const Vec3& xi, const Vec3& xj_image, const Vec3& vi,
                       const Vec3& vj, double ri, double rj, const Vec3& rate, Vec3& fi,
                       Vec3& fj) {
  const Vec3 d = xj_image - xi;
  const double r2 = dot(d, d);
  const double reach = ri + rj;
  if (r2 >= reach * reach) return;
  const double r = std::sqrt(r2);
  const double inv_r = 1.0 / r;
  const Vec3 n = d * inv_r;                          // unit normal from i to j
  const Vec3 v_rel = (vj - vi) + hadamard(rate, d);  // fluctuation + affine relative velocity
  const double fn = law(reach - r, -dot(v_rel, n));
  const Vec3 f = n * fn;
  fj += f;
  fi -= f;
}

template <class Law>
void pair_loop(const Law& law, const State& s, const NeighborList& list, const Vec3& rate,
               int begin, int end, Vec3* f) {
  Vec3 off[27];
  image_offsets(s.box, off);
  const Vec3* x = s.position.data();
  const Vec3* v = s.velocity.data();
  const double* rad = s.radius.data();
  const std::int32_t* first = list.first.data();
  const std::int32_t* partner = list.partner.data();
  const std::uint8_t* image = list.image.data();
  for (int i = begin; i < end; ++i) {
    Vec3 fi{0, 0, 0};
    const Vec3 xi = x[i], vi = v[i];
    const double ri = rad[i];
    for (int p = first[i]; p < first[i + 1]; ++p) {
      const int j = partner[p];
      pair_force(law, xi, x[j] + off[image[p]], vi, v[j], ri, rad[j], rate, fi, f[j]);
    }
    f[i] += fi;
  }
}

void add_background_damping(const Model& m, State& s) {
  const double gb = m.background_damping;
  if (gb == 0.0) return;
  for (int i = 0; i < s.count(); ++i) s.force[i] -= s.velocity[i] * gb;
}

}  // namespace

void compute_forces(const Model& model, State& s, const NeighborList& list,
                    const Vec3& rate, int threads, ForceScratch& scratch) {
  const int n = s.count();
  const LinearSpringDashpot law(model.contact);
  s.force.assign(n, Vec3{0, 0, 0});
  if (threads <= 1) {
    pair_loop(law, s, list, rate, 0, n, s.force.data());
  } else {
    scratch.per_thread.resize(threads);
#pragma omp parallel num_threads(threads)
    {
#ifdef _OPENMP
      const int t = omp_get_thread_num();
      const int nt = omp_get_num_threads();
#else
      const int t = 0, nt = 1;
#endif
      auto& buf = scratch.per_thread[t];
      buf.assign(n, Vec3{0, 0, 0});
      // Static blocks balanced by pair count.
      const long total = list.first[n];
      int begin = 0, end = n;
      {
        const long lo = total * t / nt, hi = total * (t + 1) / nt;
        begin = static_cast<int>(std::lower_bound(list.first.begin(), list.first.end() - 1, lo) -
                                 list.first.begin());
        end = static_cast<int>(std::lower_bound(list.first.begin(), list.first.end() - 1, hi) -
                               list.first.begin());
        if (t == nt - 1) end = n;
      }
      pair_loop(law, s, list, rate, begin, end, buf.data());
#pragma omp barrier
#pragma omp for schedule(static)
      for (int i = 0; i < n; ++i) {
        Vec3 sum{0, 0, 0};
        for (int q = 0; q < nt; ++q) sum += scratch.per_thread[q][i];
        s.force[i] = sum;
      }
    }
  }
  add_background_damping(model, s);
}

void compute_forces_all_pairs(const Model& model, State& s, const Vec3& rate) {
  const int n = s.count();
  const LinearSpringDashpot law(model.contact);
  const Vec3 L = s.box.length;
  s.force.assign(n, Vec3{0, 0, 0});
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j) {
      Vec3 d = s.position[j] - s.position[i];
      for (int k = 0; k < 3; ++k) d[k] -= L[k] * std::round(d[k] / L[k]);
      pair_force(law, s.position[i], s.position[i] + d, s.velocity[i], s.velocity[j],
                 s.radius[i], s.radius[j], rate, s.force[i], s.force[j]);
    }
  add_background_damping(model, s);
}

}  // namespace dem
