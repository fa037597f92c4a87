#!/usr/bin/env bash
# Installs the system libraries the GL tests need (Mesa EGL for offscreen
# rendering, Xvfb for window tests) when they are missing, or says in one line
# what to install. LLVM 19 (Dr.Jit's back end for Mitsuba's llvm variants,
# nbrdf.mitsuba) is installed where apt can, else named in a notice.
set -u
if ! compgen -G "/usr/lib/*/libLLVM-19.so*" >/dev/null && ! compgen -G "/usr/lib/llvm-19/lib/libLLVM*.so*" >/dev/null; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "setup: installing libllvm19 (Mitsuba's llvm variants)"
        (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19) >/tmp/nbrdf-apt-llvm.log 2>&1 \
            || echo "setup: apt-get could not install libllvm19 (log: /tmp/nbrdf-apt-llvm.log); nbrdf.mitsuba needs LLVM 19 (set DRJIT_LIBLLVM_PATH)" >&2
    else
        echo "setup: nbrdf.mitsuba needs LLVM 19: install libllvm19 (e.g. sudo apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH" >&2
    fi
fi
need=()
ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' || need+=(libegl1 libegl-mesa0)
ldconfig -p 2>/dev/null | grep -q 'libGL.so.1' || need+=(libgl1 libgl1-mesa-dri)
ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1 || need+=(libgl1-mesa-dri)
command -v Xvfb >/dev/null 2>&1 || need+=(xvfb)
command -v xauth >/dev/null 2>&1 || need+=(xauth)
[ ${#need[@]} -eq 0 ] && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "setup: installing system packages: ${need[*]}"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need[@]}") >/tmp/nbrdf-apt.log 2>&1 \
        || { echo "setup: apt-get failed (log: /tmp/nbrdf-apt.log); install these packages: ${need[*]}" >&2; exit 1; }
else
    echo "setup: missing system packages, please install: ${need[*]} (e.g. sudo apt-get install ${need[*]})" >&2
    exit 1
fi
