#include "common/estimation/homography.h"
