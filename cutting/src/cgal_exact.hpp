#pragma once
// The exact number type of CGAL's Epeck kernel in octocut. Include this first, before any CGAL header, in every
// translation unit that includes CGAL (all of them are in cutting/src; Epeck must mean one type in the program).
//
// CGAL 5.5 (Debian 12) makes Epeck's exact field gmpxx's mpq_class, which cancels every product by a gcd. The
// corefinement of the surface cut (PMP::corefine) builds its intersection points and triangulates the split faces
// with Epeck, and there most predicates on the constructed points are decided exactly (points on a constrained edge
// are exactly collinear with it); with mpq_class, 60% of a cut's corefinement went into gcds. Quotient<Mpzf> is
// exact as well (Mpzf is CGAL's exact binary floating-point ring, with small numbers stored inline) but never
// reduces, and it halves the corefinement's time (docs/RESULTS.md). The answers of exact predicates do not depend on
// the exact type; only the rounding of an exact construction to double may differ in its last bit.
#include <CGAL/Interval_nt.h>
#include <CGAL/Mpzf.h>
#include <CGAL/Number_types/internal/Exact_type_selector.h>
#include <CGAL/Quotient.h>
#include <gmpxx.h>

#include <cmath>
#include <utility>

#ifdef CGAL_EXACT_PREDICATES_EXACT_CONSTRUCTIONS_KERNEL_H
#error "cgal_exact.hpp must come before CGAL's kernel headers"
#endif

namespace CGAL {
namespace internal {
template <>
struct Exact_field_selector<double> {
  using Type = CGAL::Quotient<CGAL::Mpzf>;
};
}  // namespace internal

// Quotient<NT> converts to double and to intervals as num / den. A Quotient<Mpzf> is never reduced, so its numerator
// and denominator can both leave the range of double (coplanar intersections chain several divisions) while their
// ratio is an ordinary number: num / den would then give inf / inf or 0 / 0, and the lazy kernel would round an
// exact point to NaN or inf. Here both conversions fall back to the exact rational (GMP) in that case.
template <>
class Real_embeddable_traits<Quotient<Mpzf>>
    : public INTERN_QUOTIENT::Real_embeddable_traits_quotient_base<Quotient<Mpzf>> {
  // Whether num / den may be converted part by part: both within double's normal range (num may be exactly 0) and
  // den's interval clear of 0.
  static bool in_range(const Quotient<Mpzf>& q) {
    const auto usable = [](const std::pair<double, double>& i) {
      const auto fine = [](double x) { return x == 0.0 || std::isnormal(x); };
      return fine(i.first) && fine(i.second) && (i.first == i.second || (i.first != 0.0 && i.second != 0.0));
    };
    const std::pair<double, double> d = q.denominator().to_interval();
    return usable(q.numerator().to_interval()) && usable(d) && d.first != 0.0;
  }
  static mpq_class exact(const Quotient<Mpzf>& q) { return mpq_class(q.numerator()) / mpq_class(q.denominator()); }

 public:
  struct To_interval : public CGAL::cpp98::unary_function<Quotient<Mpzf>, std::pair<double, double>> {
    std::pair<double, double> operator()(const Quotient<Mpzf>& q) const {
      if (in_range(q)) {
        return (Interval_nt<>(q.numerator().to_interval()) / Interval_nt<>(q.denominator().to_interval())).pair();
      }
      return CGAL::to_interval(exact(q));
    }
  };
  struct To_double : public CGAL::cpp98::unary_function<Quotient<Mpzf>, double> {
    double operator()(const Quotient<Mpzf>& q) const {
      if (in_range(q)) return q.numerator().to_double() / q.denominator().to_double();
      return exact(q).get_d();
    }
  };
};
}  // namespace CGAL
