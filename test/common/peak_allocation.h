#pragma once
// Peak of the bytes held through operator new, for tests that bound an algorithm's memory.
// Linking peak_allocation.cpp into a test binary replaces the global operator new and delete.
#include <cstddef>

namespace paps::test {
/// Starts a new peak at the bytes held now.
void resetAllocationPeak();
/// Largest number of bytes held since the last reset, minus those held at the reset.
std::size_t allocationPeakSinceReset();
/// False where the operators could not be replaced (Clang's ThreadSanitizer links its own
/// operator new statically): the peaks are then 0, and tests skip their memory bounds.
bool allocationCounted();
}  // namespace paps::test
