// Being written.
#include "core/bake/single_bake.h"
