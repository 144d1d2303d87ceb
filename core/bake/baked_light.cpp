// Being written.
#include "core/bake/baked_light.h"
