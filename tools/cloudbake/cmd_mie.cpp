// `cloudbake mie --x X --m RE,IM`: Lorenz-Mie efficiencies of one sphere as one line of JSON.
#include <cerrno>
#include <cmath>
#include <complex>
#include <cstdlib>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "core/error.h"
#include "core/phase/lorenz_mie.h"
#include "tools/cloudbake/commands.h"

namespace cloudbake::tool {
namespace {

double parseFinite(const std::string& field, const std::string& text) {
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v)) {
    throw InputError(field + ": expected a finite number, got '" + text + "'");
  }
  return v;
}

// "1.33,-1e-5" or "1.33" (real). The imaginary part's sign is free (see lorenz_mie.h).
std::complex<double> parseRefractiveIndex(const std::string& text) {
  const size_t comma = text.find(',');
  const double re = parseFinite("--m (real part)", text.substr(0, comma));
  const double im = comma == std::string::npos
                        ? 0.0
                        : parseFinite("--m (imaginary part)", text.substr(comma + 1));
  return {re, im};
}

}  // namespace

void addMieCommand(CLI::App& app, int* exit_code) {
  struct Options {
    std::string x, m;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand("mie",
                                     "Lorenz-Mie efficiencies of a homogeneous sphere; prints "
                                     "{\"qext\",\"qsca\",\"qback\",\"g\"} as one JSON line");
  cmd->add_option("--x", opt->x, "size parameter x = 2 pi r / lambda, in [1e-8, 1e5]")->required();
  cmd->add_option("--m", opt->m,
                  "relative refractive index RE,IM; absorption may be written with either sign "
                  "of IM (1.33,-1e-5 == 1.33,1e-5)")
      ->required();
  cmd->callback([opt, exit_code] {
    const double x = parseFinite("--x", opt->x);
    MieEfficiencies e;
    try {
      e = mieEfficiencies(x, parseRefractiveIndex(opt->m));
    } catch (const InputError& err) {  // the core names its arguments mie.x and mie.m
      const std::string what = err.what();
      if (what.rfind("mie.", 0) == 0) throw InputError("--" + what.substr(4));
      throw;
    }
    const nlohmann::json out = {{"qext", e.qext}, {"qsca", e.qsca}, {"qback", e.qback}, {"g", e.g}};
    std::cout << out.dump() << std::endl;
    *exit_code = kOk;
  });
}

}  // namespace cloudbake::tool
