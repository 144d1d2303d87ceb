// Helpers shared by the tests of core/bake.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <string>

#include "core/error.h"

namespace cloudbake {

/// Expects `fn` to throw InputError whose message contains `what` (a field, grid or knob name).
inline void expectErrorNaming(const std::function<void()>& fn, const std::string& what) {
  try {
    fn();
    ADD_FAILURE() << "no error; expected one naming " << what;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

}  // namespace cloudbake
