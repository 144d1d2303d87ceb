// Being written.
#include "core/bake/baked_light_vdb.h"
