// The event record: the one declaration of the event layout. The Python EVENT_DTYPE is
// generated from this struct by the bindings, so the two can never disagree.
#pragma once

#include "config.hpp"

#include <cstdint>

namespace evstwin {

#pragma pack(push, 1)
/// One event: t in integer microseconds from the start of the simulation, pixel (x, y),
/// polarity p (1 = ON, 0 = OFF). Packed to 13 bytes, the field's usual on-disk layout
/// [('t','<i8'),('x','<u2'),('y','<u2'),('p','u1')].
struct Event {
    std::int64_t t;
    std::uint16_t x;
    std::uint16_t y;
    std::uint8_t p;
};
#pragma pack(pop)

static_assert(sizeof(Event) == 13, "Event must be packed to 13 bytes");

enum Polarity : std::uint8_t { OFF = 0, ON = 1 };

}  // namespace evstwin
