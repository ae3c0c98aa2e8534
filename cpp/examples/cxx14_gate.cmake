# cmake -DCXX=<compiler> -DINCLUDE=<cpp/include> -P cxx14_gate.cmake
# Compiles a file that includes evstwin with -std=c++14: it must fail, with evstwin's own
# "needs C++17" message first and no error from the C++17 code of the headers after it.
file(WRITE "${CMAKE_CURRENT_BINARY_DIR}/cxx14_gate.cpp" "#include <evstwin/evstwin.hpp>\nint main() { return 0; }\n")
execute_process(COMMAND "${CXX}" -std=c++14 -fsyntax-only "-I${INCLUDE}" "${CMAKE_CURRENT_BINARY_DIR}/cxx14_gate.cpp"
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
set(text "${out}${err}")
if(rc EQUAL 0)
  message(FATAL_ERROR "-std=c++14 compiled: the C++17 gate did not stop it")
endif()
string(FIND "${text}" "evstwin needs C++17" at)
if(at EQUAL -1)
  message(FATAL_ERROR "no 'evstwin needs C++17' in the compiler's output:\n${text}")
endif()
string(REGEX MATCHALL "error:" errors "${text}")
list(LENGTH errors n)
if(n GREATER 2)
  message(FATAL_ERROR "${n} errors (evstwin's message and the stop are 2):\n${text}")
endif()
message(STATUS "refused in ${n} error(s)")
