# Decides the default of FIREFLY_BUILD_PYTHON: ON when firefly is the top-level project,
# not sanitized, and Python 3 (interpreter, development files, NumPy) and pybind11 are
# found; otherwise OFF, saying why. Included by the top-level CMakeLists.txt.
set(_firefly_python_default OFF)
if(FIREFLY_IS_TOP_LEVEL OR FIREFLY_BUILD_PYTHON)
  # Debian's interpreter first: its dist-packages hold python3-numpy, python3-pytest and
  # python3-openimageio, which a pyenv or virtualenv python3 earlier on PATH may lack.
  # -DPython3_EXECUTABLE=... chooses another.
  if(NOT DEFINED Python3_EXECUTABLE AND EXISTS /usr/bin/python3)
    set(Python3_EXECUTABLE /usr/bin/python3)
  endif()
  find_package(Python3 COMPONENTS Interpreter Development.Module NumPy QUIET)
  if(Python3_FOUND)
    # Found after Python3, pybind11 uses that interpreter (its FindPython mode).
    find_package(pybind11 CONFIG QUIET)
  endif()
  if(NOT Python3_FOUND)
    set(_firefly_python_why "Python 3 with development files and NumPy not found (apt-get install python3-dev python3-numpy)")
  elseif(NOT pybind11_FOUND)
    set(_firefly_python_why "pybind11 not found (apt-get install pybind11-dev)")
  elseif(FIREFLY_SANITIZE)
    set(_firefly_python_why "FIREFLY_SANITIZE is ON (a sanitized module cannot load into an unsanitized interpreter)")
  elseif(NOT FIREFLY_IS_TOP_LEVEL)
    set(_firefly_python_why "firefly is not the top-level project")
  else()
    set(_firefly_python_default ON)
  endif()
endif()
