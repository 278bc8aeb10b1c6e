// Anchor translation unit so poise_core is a real library even before the math layer lands.
#include "poise/core/types.h"
