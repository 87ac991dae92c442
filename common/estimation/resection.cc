#include "common/estimation/resection.h"
