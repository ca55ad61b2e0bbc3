#pragma once
// Converged tip deflections of the cantilever of tests/sim/bbar_test.cpp, from another code: CalculiX (Debian
// calculix-ccx), 60 x 12 x 12 quadratic hexahedra with reduced integration (C3D20R), linear static, the same beam
// (0.1 x 0.02 x 0.02 m, E = 1e7 Pa, rho = 1000 kg/m^3), clamp (face x = 0) and load (gravity 9.81 m/s^2 along -z):
//   python3 tests/sim/reference/cantilever_ccx.py --meshes 20x4x4,40x8x8,60x12x12 --nu 0.3,0.49
// gives 3.754991e-4, 3.762014e-4, 3.763987e-4 m (nu = 0.3) and 3.613713e-4, 3.644247e-4, 3.652993e-4 m (nu = 0.49).
// The last refinement moves them by 0.05% and 0.24%. sim_bbar_reference_test (label study) reruns ccx and checks
// these values.
namespace octocut::test {

inline constexpr double kCantileverTipNu03 = 3.763987e-4;   ///< m, nu = 0.3
inline constexpr double kCantileverTipNu049 = 3.652993e-4;  ///< m, nu = 0.49

}  // namespace octocut::test
