#include "common/estimation/table_frame.h"
