#include "common/estimation/plane_fit.h"
