//! The review page's parts beyond the charts: supervisor-state bands,
//! statistics per phase, the header saying what flew, and the small
//! inline script (linked zoom and pan, a time cursor that marks the
//! vehicle on the path). The page works without the script: the SVGs are
//! complete on their own.

use std::fmt::Write as _;

use crate::svg::{Band, esc};

/// Colour of a supervisor state's band; FAILSAFE is red.
pub fn state_color(state: &str) -> &'static str {
    match state {
        "TRACKING" => "#2a7",
        "HOLDING" => "#27c",
        "STANDBY" => "#888",
        "WAITING" => "#a8a",
        "FAILSAFE" => "#d22",
        _ => "#e90",
    }
}

/// Spans of equal state as bands, from the per-tick states and times.
pub fn state_bands(t: &[f64], states: &[&str]) -> Vec<Band> {
    let mut out: Vec<Band> = Vec::new();
    let period = if t.len() > 1 {
        (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
    } else {
        0.02
    };
    for (i, (ti, s)) in t.iter().zip(states).enumerate() {
        if !ti.is_finite() {
            continue;
        }
        match out.last_mut() {
            Some(b) if b.label == *s && i > 0 => b.x1 = ti + period,
            _ => out.push(Band {
                x0: *ti,
                x1: ti + period,
                label: (*s).to_owned(),
                color: state_color(s),
            }),
        }
    }
    out
}

/// Statistics of one phase (supervisor state).
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseStats {
    /// State name.
    pub state: String,
    /// Ticks in the state.
    pub ticks: usize,
    /// Time in the state \[s\].
    pub seconds: f64,
    /// Spans (entries into the state).
    pub spans: usize,
    /// Tracking error |measured − reference| p50, p95, max \[m\].
    pub error: [f64; 3],
    /// Largest attitude command step between consecutive ticks \[deg\].
    pub max_command_step_deg: f64,
}

/// Per-phase statistics: `err` the tracking error per tick \[m\], `cmd`
/// the (roll, pitch) command per tick \[rad\].
pub fn phase_stats(
    t: &[f64],
    states: &[&str],
    err: &[f64],
    cmd: &[(f64, f64)],
    quantile: impl Fn(&[f64], f64) -> f64,
) -> Vec<PhaseStats> {
    let period = if t.len() > 1 {
        (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
    } else {
        0.0
    };
    let mut names: Vec<&str> = Vec::new();
    for s in states {
        if !names.contains(s) {
            names.push(s);
        }
    }
    names
        .into_iter()
        .map(|name| {
            let idx: Vec<usize> = (0..states.len()).filter(|&i| states[i] == name).collect();
            let e: Vec<f64> = idx.iter().map(|&i| err[i]).collect();
            let spans = idx
                .iter()
                .filter(|&&i| i == 0 || states[i - 1] != name)
                .count();
            let step = idx
                .iter()
                .filter(|&&i| i > 0 && states[i - 1] == name)
                .map(|&i| {
                    let (a, b) = (cmd[i], cmd[i - 1]);
                    (a.0 - b.0).abs().max((a.1 - b.1).abs()).to_degrees()
                })
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max);
            PhaseStats {
                state: name.to_owned(),
                ticks: idx.len(),
                seconds: idx.len() as f64 * period,
                spans,
                error: [quantile(&e, 0.5), quantile(&e, 0.95), quantile(&e, 1.0)],
                max_command_step_deg: step,
            }
        })
        .collect()
}

/// The phase table as HTML.
pub fn phase_table(stats: &[PhaseStats]) -> String {
    let mut h = String::from(
        "<table id=\"phases\"><tr><th>phase</th><th>time [s]</th><th>spans</th>\
         <th>error p50 [m]</th><th>error p95 [m]</th><th>error max [m]</th>\
         <th>largest command step [°/tick]</th></tr>\n",
    );
    let f = |v: f64| {
        if v.is_finite() {
            format!("{v:.3}")
        } else {
            "—".into()
        }
    };
    for s in stats {
        let _ = writeln!(
            h,
            "<tr data-phase=\"{0}\"><th><span class=\"swatch\" style=\"background:{1}\"></span>{0}</th>\
             <td class=\"v\">{2:.2}</td><td class=\"v\">{3}</td><td class=\"v\" data-key=\"p50\">{4}</td>\
             <td class=\"v\" data-key=\"p95\">{5}</td><td class=\"v\" data-key=\"max\">{6}</td><td class=\"v\">{7}</td></tr>",
            esc(&s.state),
            state_color(&s.state),
            s.seconds,
            s.spans,
            f(s.error[0]),
            f(s.error[1]),
            f(s.error[2]),
            f(s.max_command_step_deg)
        );
    }
    h.push_str("</table>\n");
    h
}

/// What the header says about the flight.
#[derive(Debug, Clone, Default)]
pub struct Header {
    /// The flight's name (file).
    pub flight: String,
    /// When it flew (UTC), if known.
    pub date: Option<String>,
    /// The configuration file, if given.
    pub config: Option<String>,
    /// The `[vehicle]` table as flown (TOML text), if known.
    pub vehicle: Option<String>,
    /// `sim` / `real` and how that was decided.
    pub kind: String,
}

/// The header as HTML.
pub fn header_html(h: &Header) -> String {
    let mut s = String::from("<header id=\"flight-header\"><dl>");
    let row = |s: &mut String, k: &str, v: &str| {
        let _ = write!(s, "<dt>{}</dt><dd>{}</dd>", esc(k), esc(v));
    };
    row(&mut s, "flight", &h.flight);
    row(
        &mut s,
        "dflat",
        &format!("version {}", env!("CARGO_PKG_VERSION")),
    );
    row(
        &mut s,
        "date",
        h.date
            .as_deref()
            .unwrap_or("unknown (no .tlog beside the CSV)"),
    );
    row(
        &mut s,
        "config",
        h.config
            .as_deref()
            .unwrap_or("not given (dflat review --config FILE)"),
    );
    row(&mut s, "flown on", &h.kind);
    s.push_str("</dl>");
    if let Some(v) = &h.vehicle {
        let _ = write!(
            s,
            "<details open><summary>[vehicle]</summary><pre id=\"vehicle\">{}</pre></details>",
            esc(v)
        );
    }
    s.push_str("</header>\n");
    s
}

/// UTC date and time of a Unix time in microseconds.
pub fn utc(us: u64) -> String {
    let secs = (us / 1_000_000) as i64;
    let days = secs.div_euclid(86_400);
    let rem = secs.rem_euclid(86_400);
    let (y, m, d) = dflat_records::names::civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02} UTC",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// The page's style: responsive (the charts scale to the width; two
/// columns on wide screens).
pub const STYLE: &str = "body{font-family:sans-serif;margin:0 auto;padding:0.5em 1em;max-width:1400px}\
h1{font-size:1.3em;word-break:break-all}table{border-collapse:collapse;margin:0.5em 0}\
td,th{padding:2px 8px;text-align:left;border-bottom:1px solid #ddd;font-size:0.95em}td.v{text-align:right}\
.grid{display:grid;grid-template-columns:repeat(auto-fit,minmax(min(100%,560px),1fr));gap:0.5em}\
figure{margin:0.3em 0}svg.chart{width:100%;height:auto;touch-action:none}svg.time{cursor:crosshair}\
.swatch{display:inline-block;width:0.9em;height:0.9em;margin-right:0.3em;vertical-align:middle}\
dl{display:grid;grid-template-columns:max-content 1fr;gap:0 1em;margin:0}dt{font-weight:bold}\
pre{background:#f6f6f6;padding:0.4em;overflow-x:auto}#zoom-bar{position:sticky;top:0;background:#fff;\
padding:0.3em 0;border-bottom:1px solid #ddd;z-index:1}button{margin-right:0.5em}";

/// The inline script: linked zoom (wheel, or drag a span with the
/// mouse), pan (shift + drag, or drag with two fingers), reset, and a time
/// cursor on every time chart that moves the vehicle marker on the map.
pub const SCRIPT: &str = r#"(function(){
'use strict';
var charts=[].slice.call(document.querySelectorAll('svg.time'));
if(!charts.length)return;
var NS='http://www.w3.org/2000/svg';
var full=[Infinity,-Infinity];
charts.forEach(function(c){var d=c.dataset;full[0]=Math.min(full[0],+d.x0);full[1]=Math.max(full[1],+d.x1);});
var view=[full[0],full[1]];
var label=document.getElementById('zoom-range');
function ticks(a,b){var raw=(b-a)/6,mag=Math.pow(10,Math.floor(Math.log10(raw))),step=mag*10;
[1,2,5,10].some(function(m){if(m*mag>=raw){step=m*mag;return true;}return false;});
var out=[];for(var t=Math.ceil(a/step)*step;t<=b+1e-9&&out.length<20;t+=step)out.push(Math.abs(t)<step*1e-9?0:t);return out;}
function fmt(v){return (+v.toFixed(3)).toString();}
function apply(){
charts.forEach(function(c){var d=c.dataset,x0=+d.x0,x1=+d.x1,L=+d.left,pw=+d.pw,T=+d.top,ph=+d.ph;
var s=(x1-x0)/(view[1]-view[0]),tx=L-s*L+(x0-view[0])*pw/(view[1]-view[0]);
var g=c.querySelector('g.plot');g.setAttribute('transform','translate('+tx+' 0) scale('+s+' 1)');
var xt=c.querySelector('g.xticks');while(xt.firstChild)xt.removeChild(xt.firstChild);
ticks(view[0],view[1]).forEach(function(t){var x=L+(t-view[0])/(view[1]-view[0])*pw;
var l=document.createElementNS(NS,'line');l.setAttribute('x1',x);l.setAttribute('x2',x);l.setAttribute('y1',T);l.setAttribute('y2',T+ph);l.setAttribute('stroke','#eee');xt.appendChild(l);
var tx2=document.createElementNS(NS,'text');tx2.setAttribute('x',x);tx2.setAttribute('y',T+ph+15);tx2.setAttribute('text-anchor','middle');tx2.textContent=fmt(t);xt.appendChild(tx2);});});
if(label)label.textContent='t '+view[0].toFixed(2)+' – '+view[1].toFixed(2)+' s';
document.body.dataset.view=view[0]+','+view[1];}
function timeAt(c,ev){var r=c.getBoundingClientRect(),d=c.dataset,vb=c.viewBox.baseVal;
var x=(ev.clientX-r.left)*vb.width/r.width;return view[0]+(x-(+d.left))/(+d.pw)*(view[1]-view[0]);}
function zoom(t,f){var a=t-(t-view[0])*f,b=t+(view[1]-t)*f;if(b-a<0.05)return;
view=[Math.max(full[0],a),Math.min(full[1],b)];apply();}
window.dflatZoom=function(a,b){view=[Math.max(full[0],a),Math.min(full[1],b)];apply();};
window.dflatView=function(){return view.slice();};
var track=document.querySelector('circle.vehicle'),pts=track?JSON.parse(track.dataset.track):[];
function cursor(t){charts.forEach(function(c){var d=c.dataset,L=+d.left,pw=+d.pw;var l=c.querySelector('line.cursor');
if(!l){l=document.createElementNS(NS,'line');l.setAttribute('class','cursor');l.setAttribute('stroke','#e80');l.setAttribute('stroke-width','1.5');l.setAttribute('y1',d.top);l.setAttribute('y2',+d.top+(+d.ph));c.appendChild(l);}
var x=L+(t-view[0])/(view[1]-view[0])*pw;l.setAttribute('x1',x);l.setAttribute('x2',x);});
if(track&&pts.length){var lo=0,hi=pts.length-1;while(hi-lo>1){var m=(lo+hi)>>1;if(pts[m][0]<=t)lo=m;else hi=m;}
var p=Math.abs(pts[hi][0]-t)<Math.abs(pts[lo][0]-t)?pts[hi]:pts[lo];track.setAttribute('cx',p[1]);track.setAttribute('cy',p[2]);}
var out=document.getElementById('cursor-time');if(out)out.textContent='cursor '+t.toFixed(2)+' s';}
charts.forEach(function(c){var drag=null;
c.addEventListener('wheel',function(ev){ev.preventDefault();zoom(timeAt(c,ev),ev.deltaY>0?1.25:0.8);},{passive:false});
c.addEventListener('pointerdown',function(ev){drag={t:timeAt(c,ev),pan:ev.shiftKey||ev.pointerType==='touch',view:view.slice(),x:ev.clientX};c.setPointerCapture(ev.pointerId);});
c.addEventListener('pointermove',function(ev){var t=timeAt(c,ev);cursor(t);
if(drag&&drag.pan){var r=c.getBoundingClientRect(),vb=c.viewBox.baseVal;var dt=(ev.clientX-drag.x)*vb.width/r.width/(+c.dataset.pw)*(drag.view[1]-drag.view[0]);
var a=drag.view[0]-dt,b=drag.view[1]-dt;if(a<full[0]){b+=full[0]-a;a=full[0];}if(b>full[1]){a-=b-full[1];b=full[1];}view=[a,b];apply();}});
c.addEventListener('pointerup',function(ev){if(drag&&!drag.pan){var t=timeAt(c,ev);if(Math.abs(t-drag.t)>0.05)window.dflatZoom(Math.min(t,drag.t),Math.max(t,drag.t));}drag=null;});
c.addEventListener('dblclick',function(){window.dflatZoom(full[0],full[1]);});});
var reset=document.getElementById('zoom-reset');if(reset)reset.addEventListener('click',function(){window.dflatZoom(full[0],full[1]);});
apply();
if(location.hash==='#selftest'){var m=(full[0]+full[1])/2,w=(full[1]-full[0])/10;window.dflatZoom(m-w,m+w);cursor(m);
var g=charts[0].querySelector('g.plot');document.body.dataset.selftest='zoomed '+g.getAttribute('transform')+' vehicle '+(track?track.getAttribute('cx'):'none');}
})();"#;
