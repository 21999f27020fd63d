use estimator_core::*;
#[test]
fn second_order_noise_free_is_exact() {
    // y(k) = a1 y(k-1) + a2 y(k-2) + b (u) ; static gain G = b/(1-a1-a2)
    let (a1, a2, b) = (1.6, -0.7, 0.3);
    let g = b / (1.0 - a1 - a2);
    let u = 2.5;
    let mut est = StepEstimator::<f64, 12>::new(StepConfig::new(2, g)).unwrap();
    let (mut y1, mut y2) = (0.0, 0.0);
    for k in 0..40 {
        let y = a1 * y1 + a2 * y2 + b * u;
        y2 = y1; y1 = y;
        let r = est.push(y);
        println!("{k} {:?}", r);
    }
}
