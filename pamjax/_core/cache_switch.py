"""Point JAX's persistent compilation cache at a folder, or turn it off, at any moment of a process.

JAX reads its cache settings once: the first compilation fixes the folder (`_initialize_cache` opens it once per
process) and whether the cache is used at all (`is_cache_used` decides once). Changing `jax_compilation_cache_dir`
or `jax_enable_compilation_cache` afterwards only changed the configuration: `enable_compilation_cache(B)` after
programs were compiled into A kept writing to A, and `enable_compilation_cache(d)` after
`disable_compilation_cache()` left the cache off (no request, no file; JAX 0.10.2). JAX's public
`jax.experimental.compilation_cache.compilation_cache.reset_cache` forgets both decisions, so that the next
compilation reads the settings anew; every change made here is followed by it.
"""

import warnings


def point_jax_cache(directory: str, min_compile_seconds: float) -> None:
    """JAX's persistent cache on, in `directory`, keeping programs that compiled for `min_compile_seconds` or more;
    from the next compilation on, also where earlier ones went to another folder or the cache was off."""
    import jax

    before = jax.config.jax_compilation_cache_dir, jax.config.jax_enable_compilation_cache
    jax.config.update("jax_enable_compilation_cache", True)
    jax.config.update("jax_compilation_cache_dir", directory)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", min_compile_seconds)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    if before != (directory, True) and not reset_jax_cache():
        was = "off" if not before[1] else f"in {before[0]}" if before[0] else None
        if was is not None:
            warnings.warn(f"pamjax: this JAX cannot move its compilation cache within a process (no reset_cache): "
                          f"programs compiled from now on may still be cached {was}, not in {directory}; call "
                          f"enable_compilation_cache before anything compiles, or start a new process", stacklevel=3)


def turn_off_jax_cache() -> None:
    """JAX's persistent cache off, from the next compilation on (also after programs were compiled with it)."""
    import jax

    jax.config.update("jax_enable_compilation_cache", False)
    jax.config.update("jax_compilation_cache_dir", None)
    reset_jax_cache()


def reset_jax_cache() -> bool:
    """Make JAX read its cache settings anew at the next compilation (module docstring); False where this JAX has no
    `reset_cache` (its settings then stay as the first compilation read them)."""
    try:
        from jax.experimental.compilation_cache.compilation_cache import reset_cache
    except ImportError:
        return False
    reset_cache()
    return True
