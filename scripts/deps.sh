#!/usr/bin/env bash
# Installs everything the build and the tests need on a fresh Debian 12 machine (run as root).
# Idempotent: each step checks first and returns at once when already done. With QEMU=0 (`make demo QEMU=0`) the
# firmware's needs are left out: QEMU, the ARM binutils and the embedded Rust targets. With WEB=0 (`make demo`)
# the web checks' needs are left out: Chromium, Node.js with npm, the npm packages of tests/web and the wasm32
# target (WASM=1 keeps the target, for `make web`).
set -euo pipefail
cd "$(dirname "$0")/.."

EMBREE_WHEEL_VERSION="4.4.0.post1"
EMBREE_WHEEL_SHA256="2cd0f7d5c6342e6247e31f700761689cae7829454d8c6de0c41e62124a023e1f"
EMBREE_DIR="third_party/embree/lib"
APT_PACKAGES=(libclang1-14 libclang-common-14-dev qemu-system-arm binutils-arm-none-eabi unzip fonts-dejavu-core)
TARGETS=(thumbv7em-none-eabihf thumbv6m-none-eabi)
if [ "${QEMU:-1}" = 0 ]; then
    APT_PACKAGES=(libclang1-14 libclang-common-14-dev unzip fonts-dejavu-core)
    TARGETS=()
fi
# The browser viewer runs the core as WebAssembly (`make web`, host/tests/web.rs); with WEB=0 only if WASM=1.
if [ "${WEB:-1}" != 0 ] || [ "${WASM:-0}" = 1 ]; then
    TARGETS+=(wasm32-unknown-unknown)
fi

# The .glb export's checks by others' tools (host/tests/export.rs): the Khronos glTF validator and three.js in
# headless Chromium, from tests/web's package-lock.json. Node.js and npm come from Debian unless already installed.
if [ "${WEB:-1}" != 0 ]; then
    APT_PACKAGES+=(chromium)
    command -v node >/dev/null 2>&1 || APT_PACKAGES+=(nodejs)
    command -v npm >/dev/null 2>&1 || APT_PACKAGES+=(npm)
fi

step() { printf '\n==> deps: %s\n' "$1"; }
fail() {
    printf '\nerror: deps step "%s" failed.\n%s\n' "$1" "$2" >&2
    exit 1
}

# 1. Debian packages: libclang for bindgen (embree4-sys), QEMU and arm binutils for the Cortex-M firmware.
missing=()
for p in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    step "apt packages: ${missing[*]}"
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq || fail "apt-get update" "Check that Debian's package mirrors are reachable."
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" \
        || fail "apt-get install ${missing[*]}" "Install these packages by hand, then run 'make deps' again."
fi

# 2. Rust targets: the core must build for Cortex-M4F and for Cortex-M0 (no FPU), and for WebAssembly.
installed_targets=$(rustup target list --installed 2>/dev/null || true)
for t in "${TARGETS[@]+"${TARGETS[@]}"}"; do
    if ! grep -qx "$t" <<<"$installed_targets"; then
        step "rustup target $t"
        rustup target add "$t" || fail "rustup target add $t" "Needs rustup and access to the Rust toolchain server."
    fi
done
if ! rustup component list --installed 2>/dev/null | grep -q '^clippy'; then
    step "rustup component clippy, rustfmt"
    rustup component add clippy rustfmt || fail "rustup component add" "Needs rustup."
fi

# 3. Embree 4.4.0 shared libraries, unpacked from the PyPI wheel (Debian 12 ships only Embree 3).
if [ ! -e "$EMBREE_DIR/libembree4.so" ]; then
    step "Embree 4 from the PyPI wheel embreex==$EMBREE_WHEEL_VERSION"
    tmp=$(mktemp -d)
    trap 'rm -rf "$tmp"' EXIT
    python3 -m pip download --quiet --no-deps --only-binary=:all: \
        --platform manylinux_2_28_x86_64 --python-version 3.11 --implementation cp \
        -d "$tmp" "embreex==$EMBREE_WHEEL_VERSION" \
        || fail "pip download embreex" "Needs python3 with pip and access to PyPI."
    wheel=$(ls "$tmp"/embreex-*.whl)
    echo "$EMBREE_WHEEL_SHA256  $wheel" | sha256sum --check --quiet \
        || fail "verify embreex wheel" "The wheel's sha256 differs from the pinned one; refusing to use it."
    mkdir -p "$EMBREE_DIR"
    python3 - "$wheel" "$EMBREE_DIR" <<'PY' || fail "unpack embreex wheel" "Could not extract embreex.libs/."
import sys, zipfile, os
wheel, dest = sys.argv[1], sys.argv[2]
with zipfile.ZipFile(wheel) as z:
    for name in z.namelist():
        if name.startswith("embreex.libs/") and ".so" in name:
            target = os.path.join(dest, os.path.basename(name))
            with z.open(name) as src, open(target, "wb") as out:
                out.write(src.read())
PY
    lib=$(cd "$EMBREE_DIR" && ls libembree4-*.so.4 | head -n 1)
    [ -n "$lib" ] || fail "find libembree4" "The wheel held no libembree4-*.so.4."
    ln -sf "$lib" "$EMBREE_DIR/libembree4.so"
fi
# 4. npm packages of the web checks, exactly as locked; again only when the lock is newer than the installed tree.
if [ "${WEB:-1}" != 0 ] && [ ! tests/web/node_modules/.package-lock.json -nt tests/web/package-lock.json ]; then
    step "npm ci in tests/web (gltf-validator, three, puppeteer-core)"
    (cd tests/web && npm ci --no-audit --no-fund --loglevel=error) \
        || fail "npm ci in tests/web" "Needs npm and access to the npm registry."
fi
echo "deps: all present."
