# CMake toolchain file: bare-metal Cortex-M4F (STM32F405) with Debian's gcc-arm-none-eabi 12.
set(CMAKE_SYSTEM_NAME Generic)
set(CMAKE_SYSTEM_PROCESSOR arm)
set(CMAKE_TRY_COMPILE_TARGET_TYPE STATIC_LIBRARY)

set(CMAKE_C_COMPILER arm-none-eabi-gcc)
set(CMAKE_CXX_COMPILER arm-none-eabi-g++)
set(CMAKE_ASM_COMPILER arm-none-eabi-gcc)
set(CMAKE_OBJCOPY arm-none-eabi-objcopy CACHE FILEPATH "objcopy")
set(CMAKE_SIZE arm-none-eabi-size CACHE FILEPATH "size")

# The CPU flags are also added to every target in CMakeLists.txt, so CMAKE_CXX_FLAGS given on
# the command line cannot drop them.
set(CDAM_FW_CPU_FLAGS -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16)
string(REPLACE ";" " " _cdam_fw_cpu "${CDAM_FW_CPU_FLAGS}")
set(CMAKE_C_FLAGS_INIT "${_cdam_fw_cpu}")
set(CMAKE_CXX_FLAGS_INIT "${_cdam_fw_cpu}")
set(CMAKE_EXE_LINKER_FLAGS_INIT "${_cdam_fw_cpu}")

# Target libraries come from the toolchain; host headers (Eigen) are found explicitly with
# NO_CMAKE_FIND_ROOT_PATH in CMakeLists.txt.
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
