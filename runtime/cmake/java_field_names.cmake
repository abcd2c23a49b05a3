# cmake -DDIR=... -P java_field_names.cmake: lcm-gen --java writes an LCM field named like a Java
# keyword unchanged (lcmt_chaincomp_status.final), which javac refuses. Such fields become KW_ in
# the generated sources. The wire format is unchanged: the fingerprint is a literal lcm-gen
# computed from the .lcm names, and fields are encoded by position.
set(_keywords abstract assert extends final finally implements import instanceof interface native package
              strictfp super synchronized throws transient)
file(GLOB_RECURSE _sources ${DIR}/*.java)
foreach(_file IN LISTS _sources)
  file(READ ${_file} _text)
  set(_new "${_text}")
  foreach(_kw IN LISTS _keywords)
    string(REGEX REPLACE "\\.${_kw}([^A-Za-z0-9_])" ".${_kw}_\\1" _new "${_new}")
    string(REGEX REPLACE "(public [][A-Za-z0-9_.]+ )${_kw};" "\\1${_kw}_;" _new "${_new}")
  endforeach()
  if(NOT _new STREQUAL _text)
    file(WRITE ${_file} "${_new}")
  endif()
endforeach()
