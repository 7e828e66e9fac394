//! The browser's own `Math` for the transcendental functions Rust's `f32` and
//! `f64` methods call (`sin`, `cos`, `powf`, …): defined here, they take the
//! place of the portable libm that `compiler_builtins` links into a wasm
//! module (its weak definitions), which carried about 20 KB of code the
//! browser already has (issue 47's size budget, kept with the path tracer's
//! code added). The results are the browser's, within an ulp or two of libm's.

use js_sys::Math;

macro_rules! js_math {
    ($($name:ident / $namef:ident => $js:ident ($($a:ident),+);)*) => {$(
        #[no_mangle]
        pub extern "C" fn $name($($a: f64),+) -> f64 {
            Math::$js($($a),+)
        }
        #[no_mangle]
        pub extern "C" fn $namef($($a: f32),+) -> f32 {
            Math::$js($(f64::from($a)),+) as f32
        }
    )*};
}

js_math! {
    sin / sinf => sin(x);
    cos / cosf => cos(x);
    tan / tanf => tan(x);
    asin / asinf => asin(x);
    acos / acosf => acos(x);
    atan / atanf => atan(x);
    atan2 / atan2f => atan2(y, x);
    exp / expf => exp(x);
    log / logf => log(x);
    log2 / log2f => log2(x);
    pow / powf => pow(x, y);
}
