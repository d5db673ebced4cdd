"""Headless OpenGL contexts of each kind on Mesa (EGL), driven by moderngl.

:func:`create_context` makes a moderngl context of one of :data:`KINDS`:

* ``'core'``: moderngl's own standalone EGL context (glcontext's ``egl`` backend, an OpenGL
  core profile, 3.3 or later: 4.5 on llvmpipe);
* ``'compatibility'``: an OpenGL compatibility-profile context (EGL_KHR_create_context's
  ``EGL_CONTEXT_OPENGL_PROFILE_MASK`` = compatibility; 4.5 on llvmpipe since Mesa 20), which
  runs GLSL 1.10 to 4.50 with the compatibility built-ins (``gl_FragColor``,
  ``gl_TexCoord``, ``gl_ModelViewProjectionMatrix``, ...);
* ``'es'``: an OpenGL ES 3 context (``EGL_OPENGL_ES_API``; ES 3.2 on llvmpipe), which runs
  GLSL ES 1.00 to 3.20 as WebGL 1 and 2 and mobile engines write them.

The compatibility and ES contexts are made with libEGL through ctypes on the EGL device
glcontext uses (``eglQueryDevicesEXT``, device ``GLCONTEXT_DEVICE_INDEX``, default 0: Mesa's
software device, llvmpipe, where there is no GPU) and handed to moderngl through glcontext's
backend protocol (an object with ``load`` / ``load_opengl_function``, ``release``,
``__enter__``, ``__exit__``): moderngl loads every GL function of that context with
``eglGetProcAddress`` and ``release()`` destroys it. :func:`gl_function` gives a GL function
moderngl does not wrap (the fixed-function matrices and arrays a compatibility profile reads).
:func:`describe` names a context as its driver reports it, e.g. ``"OpenGL 4.5 compatibility
profile, llvmpipe (LLVM 15.0.6, 256 bits), Mesa 22.3.6"``; :func:`glsl_version` is the newest
GLSL version it runs (450, or 320 for GLSL ES 3.20).
"""

from __future__ import annotations

import ctypes
import os
import re
import threading

__all__ = ["KINDS", "create_context", "describe", "gl_function", "glsl_version"]

KINDS = ("core", "compatibility", "es")
_BACKEND = "study-egl"  # the name moderngl asks glcontext for while attaching a context
_LOCK = threading.Lock()
# EGL enums (Khronos eglext.h / egl.h)
_EGL_NONE, _EGL_RENDERABLE_TYPE, _EGL_SURFACE_TYPE, _EGL_PBUFFER_BIT = 0x3038, 0x3040, 0x3033, 1
_EGL_OPENGL_BIT, _EGL_OPENGL_ES3_BIT = 0x0008, 0x0040
_EGL_OPENGL_API, _EGL_OPENGL_ES_API = 0x30A2, 0x30A0
_EGL_MAJOR, _EGL_MINOR, _EGL_PROFILE_MASK, _EGL_COMPAT_BIT = 0x3098, 0x30FB, 0x30FD, 0x2
_EGL_PLATFORM_DEVICE, _EGL_DRAW, _EGL_READ = 0x313F, 0x3059, 0x305A
# kind -> (renderable bit, API, context attributes, the libGL moderngl's names resolve in)
_KIND_ATTRS = {
    "compatibility": (_EGL_OPENGL_BIT, _EGL_OPENGL_API,
                      [_EGL_MAJOR, 4, _EGL_MINOR, 5, _EGL_PROFILE_MASK, _EGL_COMPAT_BIT]),
    "es": (_EGL_OPENGL_ES3_BIT, _EGL_OPENGL_ES_API, [_EGL_MAJOR, 3, _EGL_MINOR, 0]),
}  # fmt: skip
_VP = ctypes.c_void_p


class _EGL:
    """libEGL's entry points this module calls (loaded once)."""

    _lib = None

    @classmethod
    def lib(cls):
        if cls._lib is None:
            try:
                lib = ctypes.CDLL("libEGL.so.1")
            except OSError as exc:
                raise RuntimeError(
                    f"no libEGL ({exc}); install Mesa's EGL: `apt-get install libegl1 "
                    "libegl-mesa0 libgl1-mesa-dri` (scripts/setup.sh does)"
                ) from None
            lib.eglGetProcAddress.restype, lib.eglGetProcAddress.argtypes = _VP, [ctypes.c_char_p]
            lib.eglInitialize.argtypes = [_VP, _VP, _VP]
            lib.eglChooseConfig.argtypes = [_VP, ctypes.POINTER(ctypes.c_int32),
                                            ctypes.POINTER(_VP), ctypes.c_int32,
                                            ctypes.POINTER(ctypes.c_int32)]  # fmt: skip
            lib.eglBindAPI.argtypes = [ctypes.c_uint32]
            lib.eglCreateContext.restype = _VP
            lib.eglCreateContext.argtypes = [_VP, _VP, _VP, ctypes.POINTER(ctypes.c_int32)]
            lib.eglMakeCurrent.argtypes = [_VP] * 4
            lib.eglDestroyContext.argtypes = [_VP] * 2
            lib.eglGetError.restype = ctypes.c_int32
            for name in ("eglGetCurrentDisplay", "eglGetCurrentSurface", "eglGetCurrentContext"):
                getattr(lib, name).restype = _VP
            lib.eglGetCurrentSurface.argtypes = [ctypes.c_int32]
            cls._lib = lib
        return cls._lib


def _proc(name: str, restype, *argtypes):
    """The EGL or GL entry point ``name`` (``eglGetProcAddress``: EGL_KHR_get_all_proc_addresses
    gives core GL functions too) as a ctypes function; RuntimeError when there is none."""
    ptr = _EGL.lib().eglGetProcAddress(name.encode())
    if not ptr:
        raise RuntimeError(f"EGL: no entry point {name}")
    return ctypes.CFUNCTYPE(restype, *argtypes)(ptr)


def gl_function(name: str, restype, *argtypes):
    """The GL function ``name`` of the current context as a ctypes function (``restype``,
    ``argtypes`` as ctypes types)."""
    return _proc(name, restype, *argtypes)


def _display():
    """The EGL display of the device glcontext's standalone contexts use, initialized."""
    egl = _EGL.lib()
    query = _proc("eglQueryDevicesEXT", ctypes.c_uint32, ctypes.c_int32, _VP,
                  ctypes.POINTER(ctypes.c_int32))  # fmt: skip
    platform_display = _proc("eglGetPlatformDisplayEXT", _VP, ctypes.c_uint32, _VP, _VP)
    n = ctypes.c_int32()
    if not query(0, None, ctypes.byref(n)) or n.value < 1:
        raise RuntimeError(f"EGL: no device (eglQueryDevicesEXT: 0x{egl.eglGetError():x})")
    devices = (_VP * n.value)()
    query(n.value, devices, ctypes.byref(n))
    index = int(os.environ.get("GLCONTEXT_DEVICE_INDEX", "0"))
    if index >= n.value:
        raise RuntimeError(f"EGL: device {index} asked for, {n.value} found")
    dpy = platform_display(_EGL_PLATFORM_DEVICE, devices[index], None)
    if not dpy or not egl.eglInitialize(dpy, None, None):
        raise RuntimeError(f"EGL: eglInitialize failed (0x{egl.eglGetError():x})")
    return dpy


class _EGLContext:
    """A current EGL context of ``kind`` ('compatibility' or 'es') with glcontext's backend
    protocol, surfaceless (the study draws into framebuffer objects). Released, it makes the
    context that was current before it current again (moderngl's calls go to the current
    context: a renderer made before it keeps drawing)."""

    def __init__(self, kind: str):
        egl = _EGL.lib()
        self._previous = [egl.eglGetCurrentDisplay()]
        self._previous += [egl.eglGetCurrentSurface(w) for w in (_EGL_DRAW, _EGL_READ)]
        self._previous.append(egl.eglGetCurrentContext())
        bit, api, attrs = _KIND_ATTRS[kind]
        self.dpy = _display()
        want = (ctypes.c_int32 * 5)(_EGL_RENDERABLE_TYPE, bit, _EGL_SURFACE_TYPE,
                                    _EGL_PBUFFER_BIT, _EGL_NONE)  # fmt: skip
        cfg, n = _VP(), ctypes.c_int32()
        if not egl.eglChooseConfig(self.dpy, want, ctypes.byref(cfg), 1, ctypes.byref(n)) or (
            n.value < 1
        ):
            raise RuntimeError(f"EGL: no configuration renders the {kind} API")
        if not egl.eglBindAPI(api):
            raise RuntimeError(f"EGL: eglBindAPI failed (0x{egl.eglGetError():x})")
        attrs = (ctypes.c_int32 * (len(attrs) + 1))(*attrs, _EGL_NONE)
        self.ctx = egl.eglCreateContext(self.dpy, cfg, None, attrs)
        if not self.ctx:
            raise RuntimeError(
                f"EGL: this driver makes no OpenGL {kind} context "
                f"(eglCreateContext: 0x{egl.eglGetError():x})"
            )
        self.__enter__()

    def load(self, name: str) -> int:
        return _EGL.lib().eglGetProcAddress(name.encode()) or 0

    load_opengl_function = load

    def __enter__(self):
        _EGL.lib().eglMakeCurrent(self.dpy, None, None, self.ctx)

    def __exit__(self, *exc):
        _EGL.lib().eglMakeCurrent(self.dpy, None, None, None)

    def release(self):
        if self.ctx:
            egl = _EGL.lib()
            if egl.eglGetCurrentContext() == self.ctx:
                dpy, draw, read, ctx = self._previous
                if ctx:
                    egl.eglMakeCurrent(dpy, draw, read, ctx)
                else:
                    self.__exit__()
            egl.eglDestroyContext(self.dpy, self.ctx)
            self.ctx = None


def create_context(kind: str = "core"):
    """A moderngl context of ``kind`` (:data:`KINDS`), current on this thread; RuntimeError
    naming what is missing when this machine makes none."""
    try:
        import glcontext
        import moderngl
    except ImportError as exc:  # pragma: no cover - moderngl is a pinned dependency
        raise RuntimeError("moderngl is not installed; `pip install moderngl==5.13.0`") from exc
    if kind not in KINDS:
        raise ValueError(f"unknown context kind {kind!r}; known: {', '.join(KINDS)}")
    if kind == "core":
        try:
            return moderngl.create_context(standalone=True, backend="egl", require=330)
        except Exception as exc:
            raise RuntimeError(
                "could not create a headless OpenGL 3.3 context through EGL "
                f"({type(exc).__name__}: {exc}). Install Mesa's EGL and drivers, e.g. on "
                "Debian/Ubuntu `apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri` "
                "(llvmpipe needs no GPU)"
            ) from exc
    handle = _EGLContext(kind)
    with _LOCK:  # moderngl asks glcontext for the backend by name: ours, for this one call
        by_name = glcontext.get_backend_by_name
        glcontext.get_backend_by_name = lambda name: (
            (lambda *a, **kw: handle) if name == _BACKEND else by_name(name)
        )
        try:
            return moderngl.create_context(require=300 if kind == "es" else 330,
                                           backend=_BACKEND)  # fmt: skip
        except Exception as exc:
            handle.release()
            raise RuntimeError(
                f"moderngl could not drive the OpenGL {kind} context: {exc}"
            ) from exc
        finally:
            glcontext.get_backend_by_name = by_name


def _parse_version(ctx) -> tuple[bool, int, int]:
    """(ES, major, minor) of a moderngl context's ``GL_VERSION``."""
    text = ctx.info["GL_VERSION"]
    m = re.match(r"(OpenGL ES )?(\d+)\.(\d+)", text)
    if m is None:
        raise RuntimeError(f"unreadable GL_VERSION {text!r}")
    return bool(m[1]), int(m[2]), int(m[3])


def glsl_version(ctx) -> int:
    """The newest GLSL version the context runs: 100 x major + 10 x minor of its OpenGL
    version from 3.3 on (450 for OpenGL 4.5), of its GLSL ES version for an ES 3 context (320
    for ES 3.2)."""
    es, major, minor = _parse_version(ctx)
    return 100 * major + 10 * minor


def describe(ctx) -> str:
    """The context in words, as its driver reports it: ``"OpenGL 4.5 compatibility profile,
    llvmpipe (LLVM 15.0.6, 256 bits), Mesa 22.3.6"``, ``"OpenGL ES 3.2, llvmpipe ..."``."""
    es, major, minor = _parse_version(ctx)
    info = ctx.info
    mesa = re.search(r"Mesa [\w.\-]+", info["GL_VERSION"])
    if es:
        api = f"OpenGL ES {major}.{minor}"
    else:
        mask = int(info.get("GL_CONTEXT_PROFILE_MASK", 1))
        api = f"OpenGL {major}.{minor} {'compatibility' if mask & 2 else 'core'} profile"
    return ", ".join([api, info["GL_RENDERER"], *([mesa[0]] if mesa else [])])
