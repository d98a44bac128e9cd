# Included through CMAKE_PROJECT_INCLUDE by mbtrack_ros/interfaces_build.py when it builds
# these interface packages against the ROS 2 wheels of the package index (never in a
# colcon build). The wheels' exported Python targets name the wheel builder's include
# folders (Python.h, numpy); at the end of configuration each include folder that does not
# exist is replaced by this Python's (MBTRACK_PYTHON_INCLUDE) or numpy's
# (MBTRACK_NUMPY_INCLUDE) folder.
function(_mbtrack_fix_wheel_includes)
  get_property(targets DIRECTORY "${CMAKE_SOURCE_DIR}" PROPERTY IMPORTED_TARGETS)
  foreach(target IN LISTS targets)
    get_target_property(dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT dirs)
      continue()
    endif()
    set(fixed "")
    foreach(dir IN LISTS dirs)
      if(NOT dir MATCHES "^\\$<" AND NOT EXISTS "${dir}")
        if(dir MATCHES "numpy")
          set(dir "${MBTRACK_NUMPY_INCLUDE}")
        elseif(dir MATCHES "/include/python3")
          set(dir "${MBTRACK_PYTHON_INCLUDE}")
        endif()
      endif()
      list(APPEND fixed "${dir}")
    endforeach()
    set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${fixed}")
  endforeach()
endfunction()
cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _mbtrack_fix_wheel_includes)
