#include "common/estimation/table_frame.h"

#include <gtest/gtest.h>

TEST(table_frame, Placeholder) {}
