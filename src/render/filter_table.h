// The pixel filter of a render: names and checks of its parameters, and the tables its
// sampling reads (kernels/sample/filter.h), built once per renderer.
#pragma once
#include <string>
#include <vector>

#include "sample/filter.h"

namespace tuile {

// "box", "triangle", "gaussian", "mitchell", "sinc"; throws std::invalid_argument naming
// the choices otherwise.
FilterKind parse_filter_kind(const std::string& name);
// false for a name that is none of them
bool filter_kind_from_name(const std::string& name, FilterKind& out);

// What a bad parameter should be ("a finite number > 0"), "" if all are good: `param` is
// set to the pbrt-v4 parameter's name (xradius, yradius, sigma, B, C, tau).
std::string filter_problem(const FilterParams& p, std::string* param = nullptr);

// "gaussian xradius=1.5 yradius=1.5 sigma=0.5" (the parameters the filter reads).
std::string describe(const FilterParams& p);

// The view generate reads, its tables in `storage` (which must outlive the view and not
// be resized). Throws std::invalid_argument for bad parameters or a filter whose integral
// is not positive.
FilterView build_filter(const FilterParams& p, std::vector<float>& storage);

}  // namespace tuile
