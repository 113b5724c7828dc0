#include "dem/stages/curve_file.hpp"

#include <filesystem>
#include <sstream>
#include <stdexcept>

#include "dem/contact/registry.hpp"
#include "dem/io/io.hpp"
#include "dem/measure/measure.hpp"

#include <unistd.h>

namespace dem {

std::string curve_preamble(const Model& m, const std::string& stage, const Physics& physics,
                           const std::string& definition) {
  std::ostringstream o;
  o << "# dem curve: stage=" << stage << "\n"
    << "# units: SI; *_Pa pascal, *_J joule, time_s second, *_1_s per second, *_deg degree, *_rad_s radian per second; other columns dimensionless\n"
    << "# strains: true (log) box strains ln(L/L0) since the stage start, extension positive\n"
    << "# eps_v=(eps_xx+eps_yy+eps_zz)/3; eps_d, sigma_dev, F_dev = sqrt(((a-b)^2+(b-c)^2+(c-a)^2)/2) of the diagonal\n"
    << "# stress: compression positive, contact + kinetic (fluctuation) parts; p=tr/3; p_star=2<r>p/k; s_dev=sigma_dev/p\n"
    << "# fabric: F=(1/V) sum_p V_p sum_c n(x)n; C=2*contacts/N; rattlers: <4 contacts, removed recursively\n"
    << "# overlap_*_rel: overlap / smaller radius of the pair; inertial_number=max|rate| 2<r> sqrt(rho/p)\n"
    << "# t_c=" << m.t_contact << " s, dt=" << m.dt << " s, k=" << m.contact.reference_stiffness()
    << " N/m, gamma=" << m.contact.time_step_damping() << " kg/s, gamma_b=" << m.background_damping << " kg/s\n"
    << "# physics: " << physics_line(physics) << "\n"
    << "# neighbour list: skin=" << m.skin_over_rmin * m.radius_min << " m = " << m.skin_over_rmin << " r_min ("
    << (m.skin_auto ? "auto, from dt/t_c" : "set in the scene")
    << "); the list is exact, so the skin changes the cost and the order of the force sums, not the physics\n";
  o << contact::contact_preamble(m.contact, contact::pair_scale(m.contact, m.radius_min, m.density));
  if (m.contact.frictional())
    o << "# rotations: stress includes d(x)f_t (symmetric part); "
         "sliding_fraction: contacts at the Coulomb limit; E_rot_J=sum I w^2/2; omega_mean_rad_s=mean |w|; "
         "E_t_J: tangential (and rolling, twisting) springs (part of E_pot_J); W_friction_J: energy lost to sliding (and rolling, twisting) since the state began; "
         "sigma_antisym_rel=|antisymmetric contact stress|/p (torque balance: small when quasi-static)\n";
  if (definition.find("shear_shape=") != std::string::npos)
    o << "# sheared cell: strains are the log strain 0.5 ln(F F^T) (eps_xy, eps_xz, eps_yz its shear components); "
         "eps_d, sigma_dev, s_dev, F_dev are the eigenvalue (objective) forms, equal to the *_eig columns\n";
  if (!definition.empty()) o << "# definition: " << definition << "\n";
  return o.str();
}

CurveFile::CurveFile(const std::string& path, const std::string& preamble, const std::vector<std::string>& extra)
    : path_(path), part_(path + ".part") {
  ::close(create_exclusive(part_));   // never follows a planted link; the file is ours and empty
  out_.open(part_, std::ios::out | std::ios::in);
  if (!out_) throw std::runtime_error("cannot write " + part_ + ": check that the folder exists and is writable");
  std::string h;
  for (auto& c : curve_columns()) h += (h.empty() ? "" : ",") + c;
  for (auto& c : extra) h += "," + c;
  out_ << preamble << h << ",stage\n";
  check("(header)");
}

void CurveFile::row(const std::string& row, const std::string& stage) { out_ << row << "," << stage << "\n"; }

void CurveFile::check(const std::string& stage) {
  if (!out_)
    throw std::runtime_error("writing " + part_ + " failed (disk full?): stage " + stage + " stopped; " + path_ +
                             " was not written (only the incomplete .part is left); free space and run again");
}

void CurveFile::commit(const std::string& stage) {
  out_.flush();
  check(stage);
  out_.close();
  check(stage);
  std::filesystem::rename(part_, path_);
}

}  // namespace dem
