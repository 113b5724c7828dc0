// The two exceptions every layer may throw, in their own header so that the scene loader, the
// engine and the stage runners need not include each other to throw or catch them.
#pragma once
#include <stdexcept>

namespace dem {

/// Thrown for any problem with a scene: unknown key, wrong type, impossible value.
/// what() names the key and how to fix it. (`dem` exits with code 2.)
struct SceneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Thrown when a sanity check fails (non-finite values, overlap beyond the allowed fraction,
/// runaway kinetic energy). what() names the check, the particle, and the likely cause.
/// (`dem` exits with code 3 after saving the last good state.)
struct BlowUp : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace dem
