// The replay page's viewer (soabench/replay/page.py): draws the embedded JSON as SVG, one panel per model.
"use strict";
(function(){
const body=document.body;
window.addEventListener("error",function(e){body.dataset.status="error: "+e.message;});
const D=JSON.parse(document.getElementById("replay-data").textContent);
const NS="http://www.w3.org/2000/svg";
const K=D.frames.length;
const PED_FILL=["#111","#999","#fff","#8b4513"];
const AWAIT="#e6007e", EST="#5b2a86", HIDE="#4b2e83";
// one colour per track label (soabench/replay/animation.py's TRACK_COLORS): label i of a model in colour i
const TRACK=["#e6194b","#3cb44b","#4363d8","#f58231","#911eb4","#42d4f4","#f032e6","#9a6324","#469990","#800000",
  "#808000","#000075"];
function esc(s){return String(s).replace(/[&<>"']/g,c=>"&#"+c.charCodeAt(0)+";");}
function pts(a){return a.map(p=>p[0]+","+p[1]).join(" ");}
function el(tag,attrs){const e=document.createElementNS(NS,tag);for(const k in attrs)e.setAttribute(k,attrs[k]);return e;}
document.getElementById("title").textContent="soabench replay: "+D.title+" (seed "+D.seed+", SUMO seed "+D.sumo_seed+
  ", "+D.filter+" filter, mode "+D.mode+", clutter \u03bb = "+D.clutter+")";
const notes=document.getElementById("notes");
D.notes.forEach(function(n){const li=document.createElement("li");li.textContent=n;
  if(/^NOT|differ/.test(n))li.className="bad";notes.appendChild(li);});
// legend
const legend=document.getElementById("legend");
function swatch(svg,label){const s=document.createElement("span");
  s.innerHTML='<svg width="18" height="14" viewBox="0 0 18 14">'+svg+"</svg> "+esc(label);legend.appendChild(s);}
swatch('<rect x="1" y="2" width="16" height="10" fill="#7fd37f" fill-opacity="0.45"/>',"visible sidewalk \u03a9_k");
swatch('<defs><pattern id="hatch-legend" patternUnits="userSpaceOnUse" width="4" height="4" patternTransform="rotate(45)">'+
  '<line x1="0" y1="0" x2="0" y2="4" stroke="'+HIDE+'" stroke-width="1.3"/></pattern></defs>'+
  '<rect x="1" y="2" width="16" height="10" fill="'+HIDE+'" fill-opacity="0.18"/><rect x="1" y="2" width="16" height="10" fill="url(#hatch-legend)"/>',
  "occluded sidewalk in the FOV (\u03a9_k's complement: the sensor cannot see it)");
swatch('<rect x="1" y="2" width="16" height="10" fill="none" stroke="#000" stroke-dasharray="3 2"/>',"field of view");
swatch('<rect x="1" y="3" width="16" height="8" fill="#e41a1c" stroke="#000"/>',"ego (sensor)");
swatch('<rect x="1" y="3" width="16" height="8" fill="#377eb8" stroke="#000"/>',"moving vehicle");
swatch('<rect x="1" y="3" width="16" height="8" fill="#000"/>',"parked car");
swatch('<rect x="1" y="1" width="16" height="12" fill="#f5c518" stroke="#b8860b"/>',"building");
D.ped_states.forEach(function(s,i){swatch('<circle cx="9" cy="7" r="5" fill="'+PED_FILL[i]+'" stroke="#000"'+
  (i==1?' stroke-dasharray="2 1"':'')+'/>',"pedestrian: "+s);});
swatch('<circle cx="9" cy="7" r="5" fill="none" stroke="'+AWAIT+'" stroke-width="2.5"/>',"detected, not yet initiated (delay runs)");
swatch('<path d="M1 7H17" stroke="'+AWAIT+'" stroke-width="1.5" stroke-dasharray="3 2"/>',
  "to the nearest birth term (its distance in \u03c3 in the panel's line: beyond 2\u03c3, outside every ellipse)");
swatch('<circle cx="9" cy="7" r="3" fill="#1f77b4"/>',"measurement (target)");
swatch('<path d="M5 3L13 11M13 3L5 11" stroke="#ff7f0e" stroke-width="2"/>',"measurement (clutter)");
swatch('<path d="M9 1V13M3 7H15" stroke="'+EST+'" stroke-width="2.5"/>',"estimate");
if(D.models.some(m=>m.tracks&&m.tracks.length))swatch('<path d="M9 1V13M3 7H15" stroke="'+TRACK[0]+'" stroke-width="2.5"/>'+
  '<path d="M9 1V13M3 7H15" stroke="'+TRACK[1]+'" stroke-width="2.5" transform="translate(6 0)"/>',
  "estimate with its track label (one colour per track)");
D.sources.forEach(function(s){swatch('<ellipse cx="9" cy="7" rx="7" ry="4" fill="none" stroke="'+s.color+'" stroke-width="1.5"/>',
  "birth: "+s.label);});
// panels: the static scene once per panel, a dynamic layer redrawn per frame
const S=D.scene, vb=S.viewBox.join(" ");
let fs=Math.max(S.viewBox[2],S.viewBox[3])/55;
const svgs=[];
const panels=document.getElementById("panels"), layers=[], stats=[];
D.models.forEach(function(m,i){
  const div=document.createElement("div");div.className="panel";
  const h=document.createElement("h2");h.textContent=m.label+" (trial delay "+(m.delay_mean===null?"n/a":m.delay_mean.toFixed(2)+" s")+
    ", OSPA "+(m.ospa===null?"n/a":m.ospa.toFixed(1)+" m")+")";div.appendChild(h);
  const st=document.createElement("div");st.className="stats";div.appendChild(st);stats.push(st);
  const svg=el("svg",{viewBox:vb,"class":"map",preserveAspectRatio:"xMidYMid meet"});svgs.push(svg);
  svg.appendChild(el("path",{d:S.roads,fill:"#8c8c8c"}));
  svg.appendChild(el("path",{d:S.sidewalk,fill:"#fff",stroke:"#b0b0b0","stroke-width":0.15,"fill-rule":"evenodd"}));
  svg.appendChild(el("path",{d:S.crossings,fill:"#f4f4f4",stroke:"#b0b0b0","stroke-width":0.15}));
  svg.appendChild(el("path",{d:S.buildings,fill:"#f5c518",stroke:"#b8860b","stroke-width":0.3,"fill-rule":"evenodd"}));
  svg.appendChild(el("path",{d:S.parked,fill:"#000"}));
  S.doors.forEach(function(p){svg.appendChild(el("rect",{x:p[0]-0.7,y:p[1]-0.7,width:1.4,height:1.4,fill:"#8b4513"}));});
  const defs=el("defs",{}), pat=el("pattern",{id:"hatch"+i,patternUnits:"userSpaceOnUse",width:1.4,height:1.4,
    patternTransform:"rotate(45)"});
  pat.appendChild(el("line",{x1:0,y1:0,x2:0,y2:1.4,stroke:HIDE,"stroke-width":0.35}));defs.appendChild(pat);svg.appendChild(defs);
  const g=el("g",{"class":"dyn"});svg.appendChild(g);layers.push(g);
  div.appendChild(svg);panels.appendChild(div);
});
function view(f){
  const v=document.getElementById("zoom").value, z=v!="scene", h=D.r_max*(v=="near"?0.45:1.1);
  const p=focus===null?null:f.peds.find(q=>q[0]==focus), c=p?[p[1],p[2]]:f.ego, a=S.viewBox[2]/S.viewBox[3];
  const box=z?[c[0]-h*a,c[1]-h,2*h*a,2*h]:S.viewBox;
  fs=Math.max(box[2],box[3])/55;
  svgs.forEach(s=>s.setAttribute("viewBox",box.map(v=>v.toFixed(2)).join(" ")));
  body.dataset.view=v;body.dataset.focus=p?focus:"";}
function draw(k){
  const f=D.frames[k];view(f);const R=fs*0.45;
  let common='<path d="'+f.omega+'" fill="#7fd37f" fill-opacity="0.45" fill-rule="evenodd"/>'+
    '<path d="'+f.hidden+'" fill="'+HIDE+'" fill-opacity="0.18" fill-rule="evenodd"/>'+
    '<path d="'+f.hidden+'" fill="url(#hatch%I%)" fill-rule="evenodd"/>'+
    '<path d="'+f.fov+'" fill="none" stroke="#000" stroke-width="0.25" stroke-dasharray="1.5 1" fill-rule="evenodd"/>';
  f.vehicles.forEach(function(v){common+='<polygon points="'+pts(v)+'" fill="#377eb8" stroke="#000" stroke-width="0.15"/>';});
  if(f.ego_box.length)common+='<polygon points="'+pts(f.ego_box)+'" fill="#e41a1c" stroke="#000" stroke-width="0.15"/>';
  const e=f.ego, hx=e[0]+6*Math.cos(e[2]), hy=e[1]-6*Math.sin(e[2]);
  common+='<line x1="'+e[0]+'" y1="'+e[1]+'" x2="'+hx.toFixed(2)+'" y2="'+hy.toFixed(2)+'" stroke="#000" stroke-width="0.4"/>';
  let zs="";
  const c=(0.7*R).toFixed(2), c2=(1.4*R).toFixed(2);
  f.z.forEach(function(z){zs+=z[2]?'<path d="M'+(z[0]-c)+" "+(z[1]-c)+"l"+c2+" "+c2+"m0 -"+c2+"l-"+c2+" "+c2+
    '" stroke="#ff7f0e" stroke-width="'+(0.45*R)+'"/>':'<circle cx="'+z[0]+'" cy="'+z[1]+'" r="'+(0.55*R)+'" fill="#1f77b4"/>';});
  let nDrawn=0,nTracks=0;
  D.models.forEach(function(m,i){
    const mf=f.models[i];
    let s=common.replace("%I%",i), counts={};
    mf.births.forEach(function(b){
      counts[b[5]]=(counts[b[5]]||0)+1;
      s+='<ellipse cx="'+b[0]+'" cy="'+b[1]+'" rx="'+(b[2]/2)+'" ry="'+(b[3]/2)+'" transform="rotate('+b[4]+" "+b[0]+" "+b[1]+
        ')" fill="none" stroke="'+D.sources[b[5]].color+'" stroke-width="0.2" stroke-opacity="0.85"/>';});
    const waiting=[];
    f.peds.forEach(function(p){
      const st=p[3], init=p[5][i], r=st==3?R*0.8:R;
      s+=st==3?'<rect x="'+(p[1]-r)+'" y="'+(p[2]-r)+'" width="'+2*r+'" height="'+2*r+'" fill="'+PED_FILL[3]+'" fill-opacity="0.6"/>':
        '<circle cx="'+p[1]+'" cy="'+p[2]+'" r="'+r+'" fill="'+PED_FILL[st]+'" stroke="#000" stroke-width="0.2"'+
        (st==1?' stroke-dasharray="0.5 0.3"':'')+'/>';
      if(init==1){s+='<circle cx="'+p[1]+'" cy="'+p[2]+'" r="'+(2.2*R)+'" fill="none" stroke="'+AWAIT+'" stroke-width="'+(0.5*R)+'"/>';waiting.push(p[0]);}
      s+='<text x="'+(p[1]+1.3*R)+'" y="'+(p[2]-1.3*R)+'" font-size="'+fs+'" fill="#000" stroke="#fff" stroke-width="'+(fs/6)+
        '" paint-order="stroke">'+esc(p[0])+'</text>';});
    s+=zs;
    const why={};
    mf.why.forEach(function(w){why[w[0]]=w;const p=f.peds.find(q=>q[0]==w[0]);if(!p)return;
      s+='<line x1="'+p[1]+'" y1="'+p[2]+'" x2="'+w[4]+'" y2="'+w[5]+'" stroke="'+AWAIT+'" stroke-width="'+(0.45*R)+
        '" stroke-dasharray="'+R+" "+(0.6*R)+'"/>';});
    const e1=1.5*R, e2=3*R;
    mf.est.forEach(function(x){const lab=x[2]>=0?m.tracks[x[2]]:null, col=lab===null?EST:TRACK[x[2]%TRACK.length];
      s+='<path d="M'+x[0]+" "+(x[1]-e1)+"v"+e2+"M"+(x[0]-e1)+" "+x[1]+"h"+e2+'" stroke="'+col+
      '" stroke-width="'+(0.45*R)+'"/>';
      if(lab!==null)s+='<text class="track" x="'+(x[0]+1.3*R)+'" y="'+(x[1]+2.2*R)+'" font-size="'+fs+'" font-weight="bold" fill="'+
        col+'" stroke="#fff" stroke-width="'+(fs/6)+'" paint-order="stroke">'+(x[2]+1)+'</text>';});
    layers[i].innerHTML=s;nDrawn+=layers[i].childElementCount;nTracks+=layers[i].querySelectorAll("text.track").length;
    const parts=Object.keys(counts).map(c=>counts[c]+" "+D.sources[c].label);
    stats[i].textContent="births: "+(parts.length?parts.join(", "):"none")+" | estimates "+mf.est.length+
      " | components "+mf.n_comp+(mf.sum_w===null?"":" (mass "+mf.sum_w+")")+(waiting.length?" | awaiting initiation: "+waiting.map(function(id){const w=why[id];
        return w?id+" (nearest birth "+w[1].toFixed(1)+"\u03c3 away: "+D.sources[w[3]].label+", "+w[2].toFixed(1)+" m)":id;}).join(", "):"");
  });
  slider.value=k;
  document.getElementById("clock").textContent="scan k = "+k+" / "+(K-1)+", t = "+f.t.toFixed(1)+" s";
  body.dataset.frame=String(k);body.dataset.t=String(f.t);body.dataset.measurements=String(f.z.length);
  body.dataset.pedestrians=String(f.peds.length);body.dataset.drawn=String(nDrawn);
  body.dataset.tracks=String(nTracks);
}
const slider=document.getElementById("slider");slider.max=String(K-1);
let cur=0,timer=null,focus=null;  // focus: the pedestrian the zoomed views centre on (else the ego)
function go(k){cur=Math.max(0,Math.min(K-1,k|0));draw(cur);}
function stop(){if(timer){clearInterval(timer);timer=null;}document.getElementById("play").textContent="play";}
function play(){stop();if(cur>=K-1)go(0);const sp=+document.getElementById("speed").value;
  timer=setInterval(function(){if(cur>=K-1){stop();return;}go(cur+1);},1000*D.dt/sp);
  document.getElementById("play").textContent="pause";}
slider.addEventListener("input",function(){stop();go(+slider.value);});
document.getElementById("play").addEventListener("click",function(){timer?stop():play();});
document.getElementById("prev").addEventListener("click",function(){stop();go(cur-1);});
document.getElementById("next").addEventListener("click",function(){stop();go(cur+1);});
document.getElementById("zoom").addEventListener("change",function(){go(cur);});
document.getElementById("ego").addEventListener("click",function(){focus=null;go(cur);});
document.getElementById("speed").addEventListener("change",function(){if(timer)play();});
document.addEventListener("keydown",function(ev){if(ev.key=="ArrowRight"){stop();go(cur+1);}
  else if(ev.key=="ArrowLeft"){stop();go(cur-1);}else if(ev.key==" "&&ev.target==body){ev.preventDefault();timer?stop():play();}});
// the delay episodes of each model (docs/method.md 5.4); a row opens the scan of the first detection
const eps=document.getElementById("episodes");
D.models.forEach(function(m){
  const d=document.createElement("details");
  d.innerHTML="<summary>"+esc(m.label)+": "+m.episodes.length+" visibility episodes (click a row to open its first detection, centred on the pedestrian)</summary>";
  const t=document.createElement("table");t.className="ep";
  t.innerHTML="<tr><th>pedestrian</th><th>k0</th><th>k_end</th><th>k_d (detected)</th><th>k_t (initiated)</th><th>delay (s)</th></tr>";
  m.episodes.forEach(function(r){const tr=document.createElement("tr");tr.className="jump"+((r[6]||r[5]>0)?" late":"");
    tr.innerHTML="<td>"+esc(r[0])+"</td><td>"+r[1]+"</td><td>"+r[2]+"</td><td>"+r[3]+"</td><td>"+(r[4]<0?"never":r[4])+
      "</td><td>"+(r[6]?"censored":r[5].toFixed(1))+"</td>";
    tr.addEventListener("click",function(){stop();focus=r[0];const zs=document.getElementById("zoom");
      if(zs.value=="scene")zs.value="near";go(r[3]);window.scrollTo(0,0);});t.appendChild(tr);});
  d.appendChild(t);eps.appendChild(d);});
// each model's tracks: the number drawn beside an estimate (1, 2, ... by first appearance) and the tracker's label
D.models.forEach(function(m){if(!m.tracks||!m.tracks.length)return;
  const d=document.createElement("details");d.className="tracks";
  d.innerHTML="<summary>"+esc(m.label)+": "+m.tracks.length+" tracks (the number drawn beside an estimate, and its label)</summary>";
  const t=document.createElement("table");t.className="ep";
  t.innerHTML="<tr><th>track</th><th>label</th></tr>"+m.tracks.map(function(lab,i){
    return '<tr><td style="color:'+TRACK[i%TRACK.length]+';font-weight:bold">'+(i+1)+"</td><td>"+esc(lab)+"</td></tr>";}).join("");
  d.appendChild(t);eps.appendChild(d);});
function fromHash(){const m=/frame=(\d+)/.exec(location.hash);
  const fp=/focus=([^&]+)/.exec(location.hash);focus=fp?decodeURIComponent(fp[1]):null;
  const v=/view=(scene|ego|near)/.exec(location.hash);if(v)document.getElementById("zoom").value=v[1];go(m?+m[1]:0);}
window.addEventListener("hashchange",fromHash);
body.dataset.frames=String(K);
fromHash();
if(body.dataset.status=="loading")body.dataset.status="ok";
})();
