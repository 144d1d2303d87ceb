// Being written.
#include "core/bake/bake_lattice.h"
