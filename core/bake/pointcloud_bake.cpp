// Being written.
#include "core/bake/pointcloud_bake.h"
