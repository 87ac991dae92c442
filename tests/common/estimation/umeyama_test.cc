#include "common/estimation/umeyama.h"

#include <gtest/gtest.h>

TEST(umeyama, Placeholder) {}
