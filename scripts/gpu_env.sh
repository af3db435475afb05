#!/usr/bin/env bash
# Sourced by the GPU scripts: `. scripts/gpu_env.sh OUT_DIR`. Makes a headless NVIDIA GPU's
# Vulkan usable and warns when no Vulkan loader is found.
#
# In a container without a display, an ICD manifest naming libGLX_nvidia gives no Vulkan
# instance ("Could not get 'vkCreateInstance'"); the same driver's EGL library does. Where
# that is the case (and VK_ICD_FILENAMES and DISPLAY are unset), this writes a manifest naming
# libEGL_nvidia.so.0 into OUT_DIR and points VK_ICD_FILENAMES at it.
if [ "${BASH_SOURCE[0]}" = "$0" ]; then
  echo "error: source it (. scripts/gpu_env.sh OUT_DIR): run alone, its settings are lost" >&2
  exit 2
fi
gpu_env_out="${1:?usage: . scripts/gpu_env.sh OUT_DIR}"
mkdir -p "$gpu_env_out"
libs=$( (ldconfig -p || /sbin/ldconfig -p) 2>/dev/null || true)
icd=""
for f in /usr/share/vulkan/icd.d/nvidia_icd.json /etc/vulkan/icd.d/nvidia_icd.json; do
  [ -f "$f" ] && { icd=$f; break; }
done
if [ -z "${VK_ICD_FILENAMES:-}" ] && [ -z "${DISPLAY:-}" ] && [ -n "$icd" ] \
    && grep -qs libGLX_nvidia "$icd"; then
  egl=$(printf '%s\n' "$libs" | awk '/libEGL_nvidia\.so\.0 /{p=$NF} END{print p}')
  api=$(sed -n 's/.*"api_version" *: *"\([^"]*\)".*/\1/p' "$icd" | head -1)
  if [ -n "$egl" ]; then
    printf '{"file_format_version":"1.0.1","ICD":{"library_path":"%s","api_version":"%s"}}\n' \
      "$egl" "${api:-1.3.0}" > "$gpu_env_out/nvidia_egl_icd.json"
    export VK_ICD_FILENAMES="$(cd "$gpu_env_out" && pwd)/nvidia_egl_icd.json"
    echo "headless NVIDIA: Vulkan through $egl"
  fi
fi
printf '%s\n' "$libs" | grep -c 'libvulkan\.so\.1 ' >/dev/null || [ -n "${LD_LIBRARY_PATH:-}" ] \
  || echo "warning: no Vulkan loader (libvulkan.so.1): install libvulkan1 or put it on LD_LIBRARY_PATH" >&2
unset gpu_env_out libs icd egl api f
