// The bake methods this build knows, in the order docs and ServerInfo list them. Adding a method
// means one file in core/methods and one line in registry.cpp.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "core/methods/method.h"

namespace cloudbake {

/// Every registered method (immutable; one const instance each).
const std::vector<const BakeMethod*>& bakeMethods();

/// The method named `name`, or nullptr.
const BakeMethod* findMethod(std::string_view name);

/// The method of a parsed shot (the parser accepted its name, so it exists).
const BakeMethod& methodOf(const ShotSpec& shot);

/// Names of the registered methods; `runnable_only` leaves out those parsed but not run yet.
std::vector<std::string> methodNames(bool runnable_only = false);

/// "a, b or c": names for messages.
std::string joinedMethodNames(bool runnable_only = false);

}  // namespace cloudbake
